"""The oracle and the objective with every perturbation family: camera rotations leave L ~ 0, the other families
move no corner, and a runway turned out of the view is a recorded failure (never an exception)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vbl_robust.constants import FAILURE_REASONS, PENALTY_M
from vbl_robust.detect.base import DetectContext, select
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.perturb.resample import PixelScale
from vbl_robust.pipeline import Objective
from vbl_robust.space import ParameterBox

ROTATION = ParameterBox({"roll_deg": (-30, 30), "pitch_deg": (-10, 10), "yaw_deg": (-10, 10)})


@pytest.fixture(scope="module")
def scenes():
    from vbl_robust.scenes.generate import generate

    return generate(3, seed=3, width=256, height=256)


def test_any_camera_rotation_leaves_the_error_below_a_metre(scenes):
    """Roll, pitch and yaw together, in the range where the runway stays in the image (fail_outside checks it):
    the oracle's corners are the rotated camera's, so IPPE+LM finds the true position (both paths)."""
    rng = np.random.default_rng(0)
    for s in scenes:
        obj = Objective(s, OracleDetector(fail_outside=True), ROTATION, pnp="ippe_lm")
        theta = ROTATION.from_unit(rng.random((48, 3)))
        rec = obj.evaluate(theta)
        inside = ~rec.failed  # rows where the runway stayed in the image
        assert set(rec.reason) <= {"", "no_detection"} and inside.mean() > 0.75, (s.id, inside.mean())
        assert rec.loss[inside].max() < 1e-6, (s.id, rec.loss[inside].max())
        t = torch.tensor(theta[inside][:4], requires_grad=True)
        loss = obj(t).values
        loss.sum().backward()
        assert float(loss.detach().max()) < 1e-6 and torch.isfinite(t.grad).all()


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(angles=st.tuples(st.floats(-30, 30), st.floats(-10, 10), st.floats(-10, 10)))
def test_rotation_invariance_property(scenes, angles):
    obj = Objective(scenes[0], OracleDetector(), ROTATION, pnp="ippe_lm")
    assert obj(np.array([angles])).values[0] < 1e-6


def test_keypoints_at_the_detector_resolution_use_the_scaled_intrinsics(scenes):
    """Perturbing at a lower resolution (scaled K) gives the same corners in the sample's pixels."""
    s = scenes[1]
    theta = np.array([[12.0, -6.0, 7.5], [-20.0, 4.0, -3.0]])
    full = Objective(s, OracleDetector(), ROTATION).evaluate(theta)
    low = Objective(s, OracleDetector(), ROTATION, resolution=100).evaluate(theta)
    assert not Objective(s, OracleDetector(), ROTATION, resolution=100).scale.is_identity
    np.testing.assert_allclose(low.keypoints, full.keypoints, atol=1e-9)
    scale = PixelScale(0.5, 0.5)
    ctx = DetectContext.for_sample(s, Perturbation(ROTATION), theta, scale)
    np.testing.assert_allclose(ctx.sampler.K, scale.intrinsics(s.K))
    np.testing.assert_allclose(scale.to_original(select(OracleDetector().detect(ctx)).keypoints), full.keypoints,
                               atol=1e-9)


def test_the_other_families_move_no_corner(scenes):
    s = scenes[2]
    names = list(PERTURBATIONS)
    box = ParameterBox({n: PERTURBATIONS[n].levels[-1] for n in names})
    theta = box.from_unit(np.random.default_rng(1).random((3, box.dim)))
    for n in ("roll_deg", "pitch_deg", "yaw_deg"):
        theta[:, names.index(n)] = 0.0
    rec = Objective(s, OracleDetector(), box).evaluate(theta)
    truth = OracleDetector().true_corners(s)
    np.testing.assert_allclose(rec.keypoints, np.broadcast_to(truth, rec.keypoints.shape), atol=1e-9)
    assert rec.loss.max() < 1e-3


def test_a_runway_pushed_out_of_the_image_is_a_recorded_failure(scenes):
    s = scenes[0]
    box = ParameterBox({"pitch_deg": (-150, 150), "yaw_deg": (-150, 150)})
    theta = np.array([[0.0, 0.0], [40.0, 0.0], [0.0, -45.0], [120.0, 0.0], [0.0, 140.0]])
    rec = Objective(s, OracleDetector(fail_outside=True), box).evaluate(theta)
    assert rec.reason == ("", "no_detection", "no_detection", "out_of_view", "out_of_view")
    assert rec.loss.tolist()[1:] == [PENALTY_M] * 4 and rec.loss[0] < 1e-6
    # the default oracle ignores the image border, but a corner behind the camera has no image at all
    rec = Objective(s, OracleDetector(), box).evaluate(theta)
    assert rec.reason == ("", "", "", "out_of_view", "out_of_view") and "out_of_view" in FAILURE_REASONS
    assert rec.loss[:3].max() < 1e-6
    # the differentiable path: confidence 0 (low_confidence), the penalty, a zero and finite gradient
    t = torch.tensor(theta, requires_grad=True)
    ev = Objective(s, OracleDetector(), box)(t)
    loss, reasons = ev.values, ev.reasons
    loss.sum().backward()
    assert reasons[3:] == ("low_confidence",) * 2 and loss[3:].tolist() == [PENALTY_M] * 2
    assert torch.isfinite(t.grad).all() and float(t.grad[3:].abs().max()) == 0.0
