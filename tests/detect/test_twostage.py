"""The two-stage detector composes two pose models and asks the view sampler for its windows."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from detect_helpers import approach_sample

from vbl_robust.detect.base import DetectContext, DifferentiableDetector
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector
from vbl_robust.space import ParameterBox


@pytest.fixture(scope="module")
def two(tiny_pose_pt):
    return TwoStageDetector(UltralyticsDetector(tiny_pose_pt, trust=True), min_side=32)


def test_declared_capabilities(two):
    assert isinstance(two, DifferentiableDetector)
    assert two.input_size is None and two.uses_pixels and two.differentiable and two.second is two.first


def test_objective_views_agree_with_perturbing_the_image_first(two):
    """Through the Objective the views come straight from the unperturbed image; on explicitly perturbed images
    (the whole frame rendered with OpenCV first) the detector gives nearly the same keypoints."""
    from vbl_robust.pipeline import Objective

    s = approach_sample()
    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.6, 1.6)})
    obj = Objective(s, two, box, conf_threshold=0.0)

    def perturbed_first(theta):
        frames = obj.context(theta).frames()
        return np.stack([d.keypoints[0] for d in two.detect(DetectContext.of_images(frames))])

    ident = np.array([[0.0, 1.0]])
    assert np.allclose(obj.evaluate(ident).keypoints, perturbed_first(ident), atol=1e-4)
    theta = box.from_unit(np.random.default_rng(0).random((8, 2)))
    assert np.median(np.abs(obj.evaluate(theta).keypoints - perturbed_first(theta))) < 0.5  # px of 128
    t = torch.tensor(theta[:3], requires_grad=True)
    obj(t).values.sum().backward()
    assert torch.isfinite(t.grad).all()


def test_plain_images_and_the_identity_context_agree(two):
    s = approach_sample()
    from vbl_robust.pipeline import Objective

    obj = Objective(s, two, ParameterBox({"roll_deg": (-5, 5)}))
    a = two.detect(obj.context(np.zeros((1, 1))))[0]
    b = two.detect(s.image)[0]
    np.testing.assert_allclose(a.keypoints, b.keypoints, atol=1e-4)
