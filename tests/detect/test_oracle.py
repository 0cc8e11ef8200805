import numpy as np
import pytest
import torch

from vbl_robust.data.sample import Sample
from vbl_robust.detect.base import DetectContext, select
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.geometric import roll_points
from vbl_robust.perturb.resample import PixelScale
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})


def _sample(sid="s0", width=640, height=480, yaw_deg=2.0) -> Sample:
    K = intrinsics(width, height, 60.0)
    R = lard_rotation(yaw_deg=yaw_deg, pitch_lard_deg=87.0, roll_deg=-3.0, runway_azimuth_deg=0.0)
    C = np.array([-1800.0, 25.0, 110.0])
    corners = runway_corners(2500.0, 45.0)
    return Sample(sid, K, corners, project(corners, R, C, K), C, width, height, R=R)


def _ctx(sample, theta, scale=PixelScale()):
    return DetectContext.for_sample(sample, Perturbation(BOX), theta, scale)  # no pixels: the oracle reads none


def test_corners_move_with_the_roll_and_not_with_contrast():
    s = _sample()
    theta = np.array([[0.0, 1.0], [20.0, 1.0], [20.0, 2.5], [-30.0, 0.4]])
    dets = OracleDetector().detect(_ctx(s, theta))
    sel = select(dets)
    assert sel.ok.all() and np.all(sel.conf == 1.0)
    expected = roll_points(s.corners_2d, theta[:, 0], s.K[:2, 2])
    np.testing.assert_allclose(sel.keypoints, expected, atol=1e-9)
    np.testing.assert_allclose(sel.keypoints[1], sel.keypoints[2])  # contrast moves nothing
    box = dets[1].boxes[0]
    assert np.allclose(box[:2], expected[1].min(0)) and np.allclose(box[2:], expected[1].max(0))


def test_keypoints_are_in_the_detector_input_pixels():
    s = _sample()
    scale, _ = PixelScale.for_long_side(s.width, s.height, 320)
    theta = np.array([[12.0, 1.0]])
    sel = select(OracleDetector().detect(_ctx(s, theta, scale)))
    full = roll_points(s.corners_2d, theta[:, 0], s.K[:2, 2])
    np.testing.assert_allclose(scale.to_original(sel.keypoints), full, atol=1e-9)


def test_fail_outside():
    s = _sample(yaw_deg=-25.0)  # runway near the right edge: a 90° roll throws it out of the 640 x 480 frame
    theta = np.array([[0.0, 1.0], [90.0, 1.0]])
    moved = roll_points(s.corners_2d, theta[:, 0], s.K[:2, 2])
    inside = np.all((moved[..., 0] >= 0) & (moved[..., 0] <= 639) & (moved[..., 1] >= 0) & (moved[..., 1] <= 479), 1)
    assert inside.tolist() == [True, False]
    sel = select(OracleDetector(fail_outside=True).detect(_ctx(s, theta)))
    assert sel.reason == ("", "no_detection")
    assert select(OracleDetector().detect(_ctx(s, theta))).ok.all()
    conf, _ = OracleDetector(fail_outside=True).detect_top(_ctx(s, torch.from_numpy(theta)))
    assert conf.tolist() == [1.0, 0.0]


def test_noise_is_seeded_fixed_per_sample_and_scaled():
    s = _sample()
    theta = np.array([[0.0, 1.0], [5.0, 1.0]])
    a = select(OracleDetector(noise_px=2.0, seed=3).detect(_ctx(s, theta))).keypoints
    b = select(OracleDetector(noise_px=2.0, seed=3).detect(_ctx(s, theta))).keypoints
    c = select(OracleDetector(noise_px=2.0, seed=4).detect(_ctx(s, theta))).keypoints
    d = select(OracleDetector(noise_px=2.0, seed=3).detect(_ctx(_sample("other"), theta))).keypoints
    clean = roll_points(s.corners_2d, theta[:, 0], s.K[:2, 2])
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c) and not np.allclose(a, d)
    offsets = a - clean
    np.testing.assert_allclose(offsets[0], offsets[1])  # fixed in image coordinates, does not rotate
    assert 0.3 < np.std(offsets) < 6.0
    # at half resolution the same offsets in sample pixels
    scale, _ = PixelScale.for_long_side(s.width, s.height, 320)
    half = select(OracleDetector(noise_px=2.0, seed=3).detect(_ctx(s, theta, scale))).keypoints
    np.testing.assert_allclose(scale.to_original(half), a, atol=1e-9)
    # resample_noise: a new draw per call, reproducible from the seed
    o1, o2 = OracleDetector(noise_px=1.0, seed=0, resample_noise=True), OracleDetector(noise_px=1.0, resample_noise=True)
    k1, k2 = (select(o.detect(_ctx(s, theta))).keypoints for o in (o1, o2))
    np.testing.assert_array_equal(k1, k2)
    assert not np.allclose(k1, select(o1.detect(_ctx(s, theta))).keypoints)


def test_differentiable_path_matches_and_has_gradients():
    s = _sample()
    theta = torch.tensor([[7.0, 1.3], [-22.0, 0.6]], dtype=torch.float64, requires_grad=True)
    oracle = OracleDetector(noise_px=0.5)
    conf, kp = oracle.detect_top(_ctx(s, theta))
    sel = select(oracle.detect(_ctx(s, theta.detach().numpy())))
    np.testing.assert_allclose(kp.detach().numpy(), sel.keypoints, atol=1e-9)
    assert conf.tolist() == [1.0, 1.0]
    kp[:, 0, 0].sum().backward()
    assert theta.grad[:, 0].abs().min() > 0 and theta.grad[:, 1].abs().max() == 0  # roll moves, contrast not
    assert torch.autograd.gradcheck(
        lambda t: oracle.detect_top(_ctx(s, t))[1], (theta.detach().clone().requires_grad_(),)
    )


def test_projected_corners_beat_truncated_labels():
    s = _sample()
    exact = s.corners_2d.copy()
    s.corners_2d = np.floor(exact)  # LARD-style truncated labels
    np.testing.assert_allclose(OracleDetector().true_corners(s), exact, atol=1e-9)  # auto → projection
    np.testing.assert_array_equal(OracleDetector(corners="labels").true_corners(s), np.floor(exact))
    s.R = None
    np.testing.assert_array_equal(OracleDetector().true_corners(s), np.floor(exact))
    with pytest.raises(ValueError, match="no rotation"):
        OracleDetector(corners="projected").true_corners(s)


def test_errors():
    with pytest.raises(ValueError, match="noise_px"):
        OracleDetector(noise_px=-1)
    with pytest.raises(ValueError, match="corners"):
        OracleDetector(corners="gt")
    with pytest.raises(ValueError, match="needs the context"):
        OracleDetector().detect(DetectContext.of_images(torch.zeros(1, 3, 4, 4)))
