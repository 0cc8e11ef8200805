"""The view sampler: views of T(x; θ) sampled straight from the unperturbed image (perturb/views.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.detect.windows import letterbox_window
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.photometric import gray_mean
from vbl_robust.perturb.views import ViewSampler, resample, to_tensor
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})


@pytest.fixture(scope="module")
def scene():
    from vbl_robust.scenes.generate import generate

    return generate(1, seed=5)[0]


def test_direct_views_match_frame_first(scene):
    """Direct sampling (one interpolation) against rendering T(x; θ) with OpenCV first, then resampling."""
    img = scene.image
    h, w = img.shape[:2]
    theta = np.tile(np.array([[0.0, 1.0], [12.0, 1.0], [-30.0, 1.8], [7.0, 0.5]]), (3, 1))
    # letterbox (pooled by 3), a zoomed-in crop, and a crop over the top-right corner (reflection + padding)
    wins = torch.tensor([letterbox_window(h, w)] * 4 + [(300.0, 500.0, 80.0)] * 4 + [(w - 120.0, -40.0, 200.0)] * 4)
    sampler = ViewSampler(Perturbation(BOX), to_tensor(img), theta, scene.K[:2, 2])
    direct = sampler.views(wins, 320)
    ref = resample(sampler.frames(), wins, 320)
    assert torch.equal(sampler.views(wins, 320, strategy="frame"), ref)
    # the contrast's grey mean, estimated on a grid of the pooled source: within 1e-3 of the whole frame's
    unit = ViewSampler(Perturbation(BOX), to_tensor(img), np.column_stack([theta[:, 0], np.ones(12)]),
                       scene.K[:2, 2])
    assert torch.allclose(sampler.stats(), gray_mean(unit.frames()).float(), atol=1e-3)
    d = (direct - ref).abs()
    assert float(d[0].max()) < 1e-4 and float(d[4].max()) < 1e-4  # identity: the same views
    per_view = d.mean(dim=(1, 2, 3))
    assert float(per_view.max()) < 0.01, per_view  # < 2.6 grey levels on average (contrast 1.8 amplifies)
    assert float(d[8:].mean()) < 0.004  # the corner crop: reflection and grey padding where OpenCV puts them


def test_strategy_is_chosen_by_the_windows(scene):
    """Windows at the source scale: the frame is rendered first; any scaled window: direct sampling."""
    img = to_tensor(scene.image)
    theta = np.array([[5.0, 1.2]])
    s = ViewSampler(Perturbation(BOX), img, theta, scene.K[:2, 2])
    s.views(torch.tensor([[0.0, 0.0, 1024.0]]), 1024)
    assert s._frames is not None  # rendered
    s2 = ViewSampler(Perturbation(BOX), img, theta, scene.K[:2, 2])
    s2.views(torch.tensor([[0.0, 0.0, 1024.0]]), 320)
    assert s2._frames is None  # never rendered at full resolution
    with pytest.raises(ValueError, match="strategy"):
        s2.views(torch.tensor([[0.0, 0.0, 1024.0]]), 320, strategy="fast")
    with pytest.raises(ValueError, match="windows"):
        s2.views(torch.zeros(2, 3), 320)


def test_reflect_101_matches_opencv_far_outside():
    """A 40° roll of a small image reads far outside it: coordinate reflection equals BORDER_REFLECT_101."""
    rng = np.random.default_rng(0)
    img = (rng.random((24, 24, 3)) * 255).round().astype(np.uint8)
    th = np.array([[40.0, 1.0], [-75.0, 1.0]])
    s = ViewSampler(Perturbation(BOX), to_tensor(img), th, np.array([12.0, 12.0]))
    wins = torch.tensor([[0.0, 0.0, 24.0]] * 2)
    out = s.views(wins, 24, strategy="direct")
    assert torch.allclose(out, s.frames(), atol=2e-5)  # no pooling, one interpolation each: equal


def test_gradients_wrt_roll_and_contrast():
    rng = np.random.default_rng(1)
    x = torch.tensor(rng.random((1, 3, 12, 12)))
    win = torch.tensor([[-1.0, 2.0, 10.0]], dtype=torch.float64)

    def f(theta):
        return ViewSampler(Perturbation(BOX), x, theta, np.array([6.0, 6.0])).views(win, 8)

    theta = torch.tensor([[7.0, 1.3]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(f, (theta,), eps=1e-6, atol=1e-5)


def test_points_move_like_the_content():
    """A bright dot at a source pixel appears in the view where points() puts it."""
    img = np.zeros((64, 64, 3), np.uint8)
    img[20, 45] = 255
    th = np.array([[90.0, 1.0]])
    s = ViewSampler(Perturbation(BOX), to_tensor(img), th, np.array([32.0, 32.0]))
    frame = s.views(torch.tensor([[0.0, 0.0, 64.0]]), 64)[0, 0]
    v, u = np.unravel_index(int(frame.argmax()), frame.shape)
    np.testing.assert_allclose(s.points(np.array([[45.0, 20.0]]))[0, 0], (u, v), atol=1e-6)


def test_the_sampler_threads_the_intrinsics(scene):
    """K reaches the attitude homography (views, frames and points); center defaults to K's principal point."""
    img = to_tensor(scene.image)
    box = ParameterBox({"pitch_deg": (-10, 10), "roll_deg": (-10, 10)})
    theta = np.array([[4.0, -3.0]])
    with pytest.raises(ValueError, match="pitch_deg need the camera intrinsics"):
        ViewSampler(Perturbation(box), img, theta, scene.K[:2, 2])
    with pytest.raises(ValueError, match="not the principal point"):
        ViewSampler(Perturbation(box), img, theta, (1.0, 2.0), K=scene.K)
    s = ViewSampler(Perturbation(box), img, theta, K=scene.K)
    np.testing.assert_array_equal(s.center, scene.K[:2, 2])
    pt = np.array([[300.0, 700.0]])
    np.testing.assert_allclose(s.points(pt), Perturbation(box).points(pt, theta, K=scene.K))
    direct = s.views(torch.tensor([[0.0, 0.0, 1024.0]]), 256)
    framed = resample(s.frames(), torch.tensor([[0.0, 0.0, 1024.0]]), 256)
    assert float((direct - framed).abs().mean()) < 0.01  # as for roll: pooling before or after the warp
