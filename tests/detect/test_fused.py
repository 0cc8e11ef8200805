"""Views of the perturbed image sampled from the unperturbed one (two-stage detector, ``Objective(fuse=True)``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from detect_helpers import runway_image

from vbl_robust.detect.base import DetectContext
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector
from vbl_robust.detect.views import (
    letterbox_window,
    perturbed_resample,
    resample,
    rolled_gray_mean,
    to_tensor,
)
from vbl_robust.perturb import Perturbation
from vbl_robust.perturb.photometric import gray_mean
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})


@pytest.fixture(scope="module")
def scene():
    from vbl_robust.scenes import generate

    return generate(1, seed=5)[0]


def _reference(image_u8, theta, center, windows, size):
    pert = Perturbation(BOX).images_numpy(image_u8.astype(np.float32) / 255.0, theta, center=center)
    x = torch.from_numpy(pert).permute(0, 3, 1, 2)
    return resample(x, windows, size), x


def test_views_match_perturb_then_resample(scene):
    img = scene.image
    h, w = img.shape[:2]
    center = scene.K[:2, 2]
    theta = np.array([[0.0, 1.0], [12.0, 1.0], [-30.0, 1.8], [7.0, 0.5]])
    # letterbox (pooled by 3), a zoomed-in crop, and a crop over the top-right corner (reflection + padding)
    wins = torch.tensor([letterbox_window(h, w)] * 4 + [(300.0, 500.0, 80.0)] * 4 + [(w - 120.0, -40.0, 200.0)] * 4)
    th = np.tile(theta, (3, 1))
    ref, rolled = _reference(img, th, center, wins, 320)
    x = to_tensor(img)
    ang, con = torch.tensor(th[:, 0], dtype=torch.float32), torch.tensor(th[:, 1], dtype=torch.float32)
    pooled = {3: F.avg_pool2d(x, 3, 3)}
    gray = rolled_gray_mean(pooled[3], 3, h, w, ang, torch.tensor(center, dtype=torch.float32))
    # the contrast's grey mean: estimated from the pooled source within 1e-3 of the rolled image's (contrast 1 rows)
    unit = th[:, 1] == 1.0
    true = gray_mean(torch.from_numpy(Perturbation(BOX).images_numpy(img.astype(np.float32) / 255.0,
                                                                      np.column_stack([th[:, 0], np.ones(12)]),
                                                                      center=center)).permute(0, 3, 1, 2))
    assert torch.allclose(gray, true.float(), atol=1e-3)
    assert torch.allclose(gray[unit], gray_mean(rolled[unit]).float(), atol=1e-3)
    out = perturbed_resample(x, wins, 320, angle_deg=ang, center=center, contrast=con, gray_mean=gray, pooled=pooled)
    d = (out - ref).abs()
    assert float(d[0].max()) < 1e-4 and float(d[4].max()) < 1e-4  # identity: the same views
    per_view = d.mean(dim=(1, 2, 3))
    # rotated: one interpolation instead of two (and pool-then-rotate for the letterbox) — small differences only
    assert float(per_view.max()) < 0.01, per_view  # < 2.6 grey levels on average (contrast 1.8 amplifies)
    assert float(d[8:].mean()) < 0.004  # the corner crop: reflection and grey padding where OpenCV puts them


def test_reflect_101_matches_opencv_far_outside():
    """A 40° roll of a small image reads far outside it: coordinate reflection equals BORDER_REFLECT_101."""
    rng = np.random.default_rng(0)
    img = rng.random((24, 24, 3)).astype(np.float32)
    th = np.array([[40.0, 1.0], [-75.0, 1.0]])
    center = np.array([12.0, 12.0])
    wins = torch.tensor([[0.0, 0.0, 24.0]] * 2)
    ref, _ = _reference((img * 255).round().astype(np.uint8), th, center, wins, 24)
    x = torch.from_numpy((img * 255).round() / 255).permute(2, 0, 1)[None].float()
    out = perturbed_resample(x, wins, 24, angle_deg=torch.tensor(th[:, 0]).float(), center=center,
                             contrast=torch.ones(2), gray_mean=torch.zeros(2))
    assert torch.allclose(out, ref, atol=2e-5)  # no pooling, one interpolation each: equal


def test_gradients_wrt_angle_and_contrast():
    rng = np.random.default_rng(1)
    x = torch.tensor(rng.random((1, 3, 12, 12)))
    win = torch.tensor([[-1.0, 2.0, 10.0]], dtype=torch.float64)

    def f(angle, factor):
        return perturbed_resample(x, win, 8, angle_deg=angle, center=(6.0, 6.0), contrast=factor,
                                  gray_mean=torch.tensor([0.4], dtype=torch.float64))

    a = torch.tensor([7.0], dtype=torch.float64, requires_grad=True)
    c = torch.tensor([1.3], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(f, (a, c), eps=1e-6, atol=1e-5)


@pytest.fixture(scope="module")
def two(tiny_pose_pt):
    return TwoStageDetector(UltralyticsDetector(tiny_pose_pt, trust=True), min_side=32)


def _sample(size=128):
    from vbl_robust.data.sample import Sample
    from vbl_robust.geometry.camera import intrinsics, project, rot_y, runway_corners

    img, _ = runway_image(size, seed=3)
    K, z = intrinsics(size, size), runway_corners(3000.0, 45.0)
    C = np.array([-2000.0, 0.0, 2000.0 * np.tan(np.radians(3.0))])
    return Sample(id="s", K=K, corners_3d=z, corners_2d=project(z, rot_y(3.0), C, K), position=C, width=size,
                  height=size, _image=img)


def test_objective_fused_agrees_with_perturb_first(two):
    from vbl_robust.pipeline import Objective

    s = _sample()
    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.6, 1.6)})
    fused, plain = (Objective(s, two, box, conf_threshold=0.0, fuse=f) for f in (True, False))
    assert fused.fused and not plain.fused
    ident = np.array([[0.0, 1.0]])
    assert np.allclose(fused.evaluate(ident).keypoints, plain.evaluate(ident).keypoints, atol=1e-4)
    theta = box.from_unit(np.random.default_rng(0).random((8, 2)))
    a, b = fused.evaluate(theta), plain.evaluate(theta)
    assert np.allclose(a.conf, b.conf, atol=0.05)
    assert np.median(np.abs(a.keypoints - b.keypoints)) < 0.5  # pixels of a 128-px image
    t = torch.tensor(theta[:3], requires_grad=True)
    loss = fused.torch(t)
    loss.sum().backward()
    assert torch.isfinite(t.grad).all()


def test_fusion_contract(two):
    s = _sample()
    pert = Perturbation(BOX)
    assert two.applies_perturbation(pert)
    off = TwoStageDetector(two.first, fuse=False)
    assert not off.applies_perturbation(pert)
    ctx = DetectContext(s, np.array([[3.0, 1.2]]), pert, perturbed=False)
    with pytest.raises(ValueError, match="cannot apply"):
        off.detect(to_tensor(s.image), context=ctx)
    # a context marking the images as already perturbed: used as given (same as no context)
    x = to_tensor(s.image)
    done = DetectContext(s, np.array([[3.0, 1.2]]), pert)
    assert np.allclose(two.detect(x, context=done)[0].keypoints, two.detect(x)[0].keypoints)
