import numpy as np
import pytest
import torch

from vbl_robust.constants import CONF_THRESHOLD
from vbl_robust.detect.base import Detections, Detector, DifferentiableDetector, select


def _dets(confs, offset=0.0):
    m = len(confs)
    kp = np.arange(m, dtype=float)[:, None, None] + offset + np.zeros((m, 4, 2))
    return Detections(np.zeros((m, 4)), np.array(confs, dtype=float), kp)


def test_max_confidence_wins_and_threshold_applies():
    s = select([_dets([0.3, 0.9, 0.5]), _dets([0.2, 0.1]), Detections.empty(), _dets([0.25])])
    assert s.ok.tolist() == [True, False, False, True]
    assert s.reason == ("", "low_confidence", "no_detection", "")
    assert s.keypoints[0, 0, 0] == 1.0  # the candidate of confidence 0.9
    np.testing.assert_allclose(s.conf[:2], [0.9, 0.2])
    assert np.isnan(s.conf[2])
    assert np.isnan(s.keypoints[1]).all() and np.isnan(s.keypoints[2]).all()  # failures carry no keypoints
    assert CONF_THRESHOLD == 0.25  # the paper's τ_conf; exactly τ is accepted (row 3)


def test_threshold_is_a_parameter_and_ties_take_the_first():
    s = select(_dets([0.6, 0.6]), conf_threshold=0.7)
    assert s.reason == ("low_confidence",)
    s = select(_dets([0.6, 0.6]), conf_threshold=0.5)
    assert s.ok.tolist() == [True] and s.keypoints[0, 0, 0] == 0.0
    with pytest.raises(ValueError, match="conf_threshold"):
        select([], conf_threshold=1.5)


def test_nan_confidence_never_wins():
    s = select(_dets([np.nan, 0.4]))
    assert s.ok.tolist() == [True] and s.keypoints[0, 0, 0] == 1.0
    assert select(_dets([np.nan])).reason == ("low_confidence",)


def test_detections_accept_tensors_and_check_shapes():
    d = Detections(torch.zeros(2, 4), torch.tensor([0.5, 0.7]), torch.ones(2, 4, 2, requires_grad=True))
    assert isinstance(d.keypoints, np.ndarray) and d.keypoints.shape == (2, 4, 2) and len(d) == 2
    with pytest.raises(ValueError, match=r"keypoints must have shape \(2, 4, 2\) for 2 candidates, got \(3, 4, 2\)"):
        Detections(np.zeros((2, 4)), np.zeros(2), np.zeros((3, 4, 2)))


def test_protocols_are_structural():
    class BlackBox:
        input_size = None
        uses_pixels = True
        differentiable = False

        def detect(self, context):
            return [Detections.empty() for _ in range(len(context))]

    class WhiteBox(BlackBox):
        differentiable = True

        def detect_top(self, context):
            return torch.zeros(len(context)), torch.zeros(len(context), 4, 2)

    assert isinstance(BlackBox(), Detector) and not isinstance(BlackBox(), DifferentiableDetector)
    assert isinstance(WhiteBox(), DifferentiableDetector)
