"""Views: letterbox/crop resampling and the coordinate mapping that goes with it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.detect.windows import letterbox_window
from vbl_robust.perturb.views import image_to_view, resample, view_to_image


def _centroid(v):
    w = v[0, 0].double()
    ys, xs = torch.meshgrid(torch.arange(w.shape[0]), torch.arange(w.shape[1]), indexing="ij")
    return float((w * xs).sum() / w.sum()), float((w * ys).sum() / w.sum())


@pytest.mark.parametrize("zoom", [1.0, 2.0, 0.5, 0.25])
def test_point_maps_to_its_view_position(zoom):
    """A blob centred at OpenCV (u, v) lands (centroid) where image_to_view puts it, for up- and downscaling."""
    u, v = 30.3, 21.8
    ys, xs = torch.meshgrid(torch.arange(64.0), torch.arange(64.0), indexing="ij")
    blob = torch.exp(-((xs - u) ** 2 + (ys - v) ** 2) / (2 * (2.0 / zoom) ** 2)).double()
    img = blob.expand(1, 3, 64, 64)
    size = 32
    win = torch.tensor((u + 0.5 - 0.37 * size / zoom, v + 0.5 - 0.61 * size / zoom, size / zoom), dtype=torch.float64)
    out = resample(img, win, size) - resample(torch.zeros_like(img), win, size)  # remove the grey padding
    expect = image_to_view(np.array([[u, v]]), tuple(win.tolist()), size)[0]
    assert _centroid(out) == pytest.approx(tuple(expect), abs=0.02 * max(1.0, zoom))
    back = view_to_image(torch.tensor(expect + 0.5)[None, None], win, size)
    assert back[0, 0].tolist() == pytest.approx([u, v], abs=1e-9)


def test_letterbox_identity_and_padding():
    x = torch.rand(2, 3, 40, 64)
    out = resample(x, torch.tensor(letterbox_window(40, 64)), 64)
    assert torch.allclose(out[:, :, 12:52], x, atol=1e-6)
    assert torch.allclose(out[:, :, :12], torch.full_like(out[:, :, :12], 114 / 255))


def test_gradcheck_image_and_window():
    x = torch.rand(1, 3, 12, 12, dtype=torch.float64, requires_grad=True)
    w = torch.tensor([[1.3, 2.1, 7.7]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, b: resample(a, b, 5), (x, w))


@pytest.mark.parametrize("window", [(0, 0, 16), (-3, 5, 16), (10, -6, 16), (-12, 0, 16), (2, 1, 16)])
def test_integer_window_copy_equals_bilinear_sampling(window):
    """A window of the output size at integer offsets is served as a pixel copy: same values, padding and
    image gradient as the bilinear path (forced by a window that needs a gradient)."""
    torch.manual_seed(0)
    img = torch.rand(2, 3, 20, 24, dtype=torch.float64, requires_grad=True)
    fast = resample(img, torch.tensor(window, dtype=torch.float64), 16)
    slow = resample(img, torch.tensor(window, dtype=torch.float64, requires_grad=True), 16)
    assert torch.allclose(fast, slow, atol=1e-12)
    w = torch.rand_like(fast)
    g_fast, = torch.autograd.grad((fast * w).sum(), img)
    g_slow, = torch.autograd.grad((slow * w).sum(), img)
    assert torch.allclose(g_fast, g_slow, atol=1e-12)


def test_non_integer_or_mixed_windows_still_sample():
    img = torch.rand(2, 3, 16, 16, dtype=torch.float64)
    half = resample(img, torch.tensor((0.5, 0.0, 16.0), dtype=torch.float64), 16)
    # half a pixel to the right: the mean of two neighbouring columns
    assert torch.allclose(half[:, :, :, :-1], (img[:, :, :, :-1] + img[:, :, :, 1:]) / 2, atol=1e-12)
    same = resample(img, torch.tensor((0.0, 0.0, 16.0), dtype=torch.float64), 16)
    slow = resample(img, torch.tensor((0.0, 0.0, 16.0), dtype=torch.float64, requires_grad=True), 16)
    assert torch.equal(same, img) and torch.allclose(slow, img, atol=1e-12)
    mixed = resample(img, torch.tensor([(0.0, 0.0, 16.0), (1.0, 0.0, 16.0)], dtype=torch.float64), 16)
    assert torch.allclose(mixed[0], img[0]) and torch.allclose(mixed[1, :, :, :-1], img[1, :, :, 1:])
