"""The OpenCV kernel of the black-box views (perturb/warp.py) against the torch kernel it replaces on the CPU.

The torch kernel (``ViewSampler.opencv = False``) is the implementation before issue 50, kept as the differentiable
and accelerator path: it is the reference here. Run in float32 it carries its own rounding (its coordinates reach
~1e-4 px at 1000 px); run on a float64 source it gives the views those float32 coordinates approximate. The OpenCV
kernel must agree with the float64 reference within 1e-5 and with the float32 one within the float32 one's own
distance to the reference (plus 1e-5), for every registered family and both detector designs' windows; and the
shipped detector's keypoints must move by less than 1e-3 px.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.detect.windows import letterbox_window
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.registry import PERTURBATIONS, family_of
from vbl_robust.perturb.views import ViewSampler, reflect101
from vbl_robust.perturb.warp import empty_output, grid_matrix, reflect101_np
from vbl_robust.space import ParameterBox

#: strong values of each family (as tests/perturb/test_families.py)
STRONG = {"roll_deg": 12.0, "pitch_deg": 6.0, "yaw_deg": -8.0, "blur_px": 1.7, "motion_blur_px": 5.5, "haze": 0.4,
          "contrast": 1.6, "brightness": 0.15, "gamma": 0.6, "noise_std": 0.05}
#: boxes beyond one family: the audit's (roll, contrast), the whole camera attitude with every photometric family
COMBOS = [("roll_deg", "contrast"), ("roll_deg", "pitch_deg", "yaw_deg", "haze", "contrast", "brightness", "gamma")]
CASES = [(name,) for name in PERTURBATIONS] + COMBOS


@pytest.fixture(scope="module")
def scene():
    from vbl_robust.scenes.generate import generate

    return generate(1, seed=3)[0]


def _theta(names, n=4, seed=0):
    """``n`` rows: the identity, the strong values, and random points between (per parameter)."""
    rng = np.random.default_rng(seed)
    ident = np.array([PERTURBATIONS[k].identity for k in names])
    strong = np.array([STRONG[k] for k in names])
    u = np.concatenate([[0.0, 1.0], rng.uniform(-1.0, 1.0, n - 2)])
    theta = ident + u[:, None] * (strong - ident)
    for j, k in enumerate(names):  # keep one-sided families in their domain
        theta[:, j] = np.clip(theta[:, j], PERTURBATIONS[k].minimum, PERTURBATIONS[k].maximum)
    return theta


def _windows(h, w, n):
    """The letterbox (pooled by 3), and crops: magnified (p = 1), across the top-right corner (reflection, grey
    pad), pooled by 2, and wholly outside the frame."""
    lb = torch.tensor(letterbox_window(h, w), dtype=torch.float32).expand(n, 3)
    crops = torch.tensor([[401.3, 512.7, 97.0], [w - 70.0, -45.0, 140.0], [180.0, 240.0, 700.0],
                          [w + 30.0, 100.0, 64.0]], dtype=torch.float32)
    return {"letterbox": lb, "crops": crops[torch.arange(n) % 4]}


def _views(box, image, theta, K, windows, *, opencv=True, dtype=torch.float32):
    old = ViewSampler.opencv
    ViewSampler.opencv = opencv
    try:
        s = ViewSampler(Perturbation(box), image.to(dtype), theta, K=K)
        return s.views(windows.to(dtype), 320)
    finally:
        ViewSampler.opencv = old


@pytest.mark.parametrize("names", CASES, ids=["+".join(c) for c in CASES])
def test_opencv_views_match_the_torch_kernel(scene, names):
    """Every family, the single pass's and the two-stage's windows: the same views as the torch kernel."""
    image = torch.from_numpy(scene.image).permute(2, 0, 1).float() / 255.0
    theta = _theta(names)
    box = list(names)
    for what, win in _windows(*scene.image.shape[:2], len(theta)).items():
        fast = _views(box, image, theta, scene.K, win)
        old = _views(box, image, theta, scene.K, win, opencv=False)
        if Perturbation(box).needs_frame:  # optical / noise families: frames first, the same code either way
            assert torch.equal(fast, old), what
            continue
        ref = _views(box, image, theta, scene.K, win, opencv=False, dtype=torch.float64)
        err_fast = float((fast.double() - ref).abs().max())
        err_old = float((old.double() - ref).abs().max())
        assert err_fast < 1e-5, (what, err_fast, err_old)
        assert float((fast - old).abs().max()) <= err_old + 1e-5, what


def test_contrast_statistics_match_the_torch_kernel(scene):
    image = torch.from_numpy(scene.image).permute(2, 0, 1).float() / 255.0
    theta = _theta(("roll_deg", "pitch_deg", "contrast"), n=6)
    box = ["roll_deg", "pitch_deg", "contrast"]
    fast = ViewSampler(Perturbation(box), image, theta, K=scene.K).stats()
    ViewSampler.opencv = False
    try:
        old = ViewSampler(Perturbation(box), image, theta, K=scene.K).stats()
    finally:
        ViewSampler.opencv = True
    assert float((fast - old).abs().max()) < 1e-6


def test_a_view_behind_the_camera_takes_the_torch_kernel():
    """A pitch beyond the field of view puts samples behind the camera (w ≤ 0): the torch kernel's values."""
    rng = np.random.default_rng(0)
    image = torch.from_numpy(rng.random((3, 96, 128), dtype=np.float32))
    K = np.array([[60.0, 0.0, 64.0], [0.0, 60.0, 48.0], [0.0, 0.0, 1.0]])
    theta = np.array([[75.0, 0.0], [5.0, 3.0]])
    win = torch.tensor([[0.0, -16.0, 128.0]]).expand(2, 3)
    fast = _views(["pitch_deg", "yaw_deg"], image, theta, K, win)
    old = _views(["pitch_deg", "yaw_deg"], image, theta, K, win, opencv=False)
    assert torch.equal(fast, old)


@pytest.mark.parametrize("name", [k for k, spec in PERTURBATIONS.items() if spec.kind == "photometric"])
def test_in_place_pointwise_equals_the_pointwise_map(name):
    rng = np.random.default_rng(1)
    values = torch.from_numpy(rng.random((3, 3, 9, 7), dtype=np.float32))
    fam = family_of(name)
    v = {name: torch.tensor([STRONG[name], PERTURBATIONS[name].identity, 0.5 * STRONG[name] + 0.3],
                            dtype=torch.float64)}
    stats = torch.tensor([0.4, 0.5, 0.6])
    want = fam.pointwise(values, v, stats)
    got = values.clone()
    assert fam.pointwise_(got, v, stats) is got
    assert torch.equal(got, want)


@pytest.mark.parametrize("names", [("roll_deg",), ("roll_deg", "pitch_deg", "yaw_deg"), ("contrast",)])
def test_source_matrices_are_the_inverse_map(scene, names):
    """The homographies of the OpenCV kernel map points as ``source_coords`` does (float64)."""
    p = Perturbation(list(names))
    theta = _theta(names, n=5, seed=2)
    center, K = scene.K[:2, 2], scene.K
    h = p.source_matrices(theta, center, K)
    q = np.random.default_rng(3).uniform(-100.0, 1100.0, (5, 7, 2))
    qu, qv = (torch.from_numpy(q[..., k]) for k in (0, 1))
    su, sv = p.source_coords(qu, qv, torch.from_numpy(theta), torch.from_numpy(center), torch.from_numpy(K))
    x = np.einsum("bij,bpj->bpi", h, np.concatenate([q, np.ones((5, 7, 1))], axis=-1))
    np.testing.assert_allclose(x[..., 0] / x[..., 2], su.numpy(), atol=1e-8)
    np.testing.assert_allclose(x[..., 1] / x[..., 2], sv.numpy(), atol=1e-8)


def test_reflection_and_grids():
    u = np.linspace(-5000.0, 5000.0, 2001)
    np.testing.assert_allclose(reflect101_np(u, 1024), reflect101(torch.from_numpy(u), 1024).numpy(), atol=1e-9)
    q = grid_matrix(np.array([10.0]), np.array([-4.0]), 2.5, 0.5)[0]
    # pixel centre j sits at edge coordinate x0 + (j + ½)·step, i.e. OpenCV coordinate x0 + (j + ½)·step − ½
    np.testing.assert_allclose(q @ [3.0, 2.0, 1.0], [10.0 + 3.5 * 2.5 - 0.5, -4.0 + 2.5 * 0.5 - 0.5, 1.0])
    t = empty_output(4, 3, 320, 320)
    assert t.shape == (4, 3, 320, 320) and t.dtype == torch.float32 and t.is_contiguous()


@pytest.mark.parametrize("design", ["single", "twostage"])
def test_shipped_detector_outputs_move_less_than_a_thousandth_of_a_pixel(scene, design):
    """The shipped model on both kernels' views: the same candidates, keypoints within 1e-3 px."""
    from vbl_robust.detect.shipped import default_detector
    from vbl_robust.pipeline import Objective

    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    theta = box.from_unit(np.random.default_rng(4).random((6, 2)))
    det = default_detector(design=design, engine="torch")
    fast = Objective(scene, det, box).evaluate(theta)
    ViewSampler.opencv = False
    try:
        old = Objective(scene, det, box).evaluate(theta)
    finally:
        ViewSampler.opencv = True
    assert fast.reason == old.reason
    np.testing.assert_allclose(fast.keypoints, old.keypoints, atol=1e-3)
    np.testing.assert_allclose(fast.conf, old.conf, atol=1e-4)


@pytest.mark.parametrize("names", CASES, ids=["+".join(c) for c in CASES])
def test_frames_channels_first_are_the_frames_transposed(image, names):
    """The single pass's frames, rendered one scratch frame at a time and split into planes: the same numbers."""
    K = np.array([[140.0, 0.0, 83.0], [0.0, 140.0, 57.5], [0.0, 0.0, 1.0]])
    p, theta = Perturbation(list(names)), _theta(names)
    hwc = p.images_numpy(image, theta, K=K)
    chw = p.images_numpy(image, theta, K=K, channels_first=True)
    assert chw.flags["C_CONTIGUOUS"] and np.array_equal(chw, hwc.transpose(0, 3, 1, 2))
