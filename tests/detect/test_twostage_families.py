"""The two-stage detector with every perturbation family: all through the one view sampler (crop windows are
cut from T(x; θ), points moved by its geometry), on both paths."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from detect_helpers import approach_sample

from vbl_robust.detect.base import DetectContext
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.pipeline import Objective
from vbl_robust.space import ParameterBox

ALL = ParameterBox({n: spec.levels[2] for n, spec in PERTURBATIONS.items()})


@pytest.fixture(scope="module")
def two(tiny_pose_pt):
    return TwoStageDetector(UltralyticsDetector(tiny_pose_pt, trust=True), min_side=32)


@pytest.mark.parametrize("names", [("pitch_deg", "yaw_deg", "haze", "brightness", "gamma"),
                                   ("blur_px", "motion_blur_px", "noise_std", "roll_deg")])
def test_views_through_the_objective_agree_with_perturbing_first(two, names):
    """Crops the detector asks for equal crops of the whole perturbed frames: exactly for the optical and noise
    families (frames first), within interpolation smoothing for the others (sampled straight from the source)."""
    s = approach_sample()
    box = ParameterBox({n: PERTURBATIONS[n].levels[2] for n in names})
    obj = Objective(s, two, box, conf_threshold=0.0)

    def perturbed_first(theta):
        frames = obj.context(theta).frames()
        return np.stack([d.keypoints[0] for d in two.detect(DetectContext.of_images(frames))])

    theta = box.from_unit(np.random.default_rng(0).random((6, box.dim)))
    diff = np.abs(obj.evaluate(theta).keypoints - perturbed_first(theta))
    if obj.perturbation.needs_frame:
        assert diff.max() < 1e-4
    else:
        assert np.median(diff) < 0.5  # px of 128 (as for roll and contrast)


def test_every_family_at_once_on_both_paths(two):
    s = approach_sample()
    obj = Objective(s, two, ALL, conf_threshold=0.0)
    theta = ALL.from_unit(np.random.default_rng(1).random((4, ALL.dim)))
    rec = obj.evaluate(theta)
    assert rec.loss.shape == (4,) and np.isfinite(rec.loss).all()
    assert set(rec.reason) <= {"", "pnp_failed", "non_finite_position"}
    t = torch.tensor(theta[:2], requires_grad=True)
    obj(t).values.sum().backward()
    assert torch.isfinite(t.grad).all()
