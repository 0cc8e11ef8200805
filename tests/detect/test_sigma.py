"""Issue 49: a detector that says how sure it is — YOLO26-pose's per-corner σ carried from the network through the
engines, the detections and PnP to a runtime monitor."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from vbl_robust.detect.base import Detections, select
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.detect.pose import split_raw, split_sigma
from vbl_robust.pipeline import Objective
from vbl_robust.pnp.differentiable import position_jacobian_fd, position_sigma
from vbl_robust.pnp.solvers import solve
from vbl_robust.scenes.generate import generate
from vbl_robust.space import ParameterBox

IMGSZ = 64


@pytest.fixture(scope="module")
def yolo26_pt(tmp_path_factory) -> str:
    """An untrained YOLO26n-pose checkpoint with the runway head (1 class, 4 corners): plumbing, not accuracy."""
    from vbl_robust.detect.offline import import_ultralytics

    import_ultralytics()
    from ultralytics.nn.tasks import PoseModel

    torch.manual_seed(0)
    model = PoseModel("yolo26n-pose.yaml", nc=1, data_kpt_shape=(4, 3), verbose=False)
    model.names = {0: "runway"}
    with torch.no_grad():  # a σ head that varies by anchor, so that a wrong gather shows
        for conv in model.model[-1].cv4_sigma:
            conv.bias.uniform_(-2.0, 2.0)
    path = tmp_path_factory.mktemp("y26") / "y26.pt"
    torch.save({"model": model, "train_args": {"imgsz": IMGSZ}}, path)
    return str(path)


def test_the_raw_output_carries_each_anchors_sigma_and_the_same_keypoints(yolo26_pt):
    from vbl_robust.detect.ultralytics import UltralyticsDetector, load_pose_model

    det = UltralyticsDetector(yolo26_pt, trust=True)
    assert det.gives_sigma and det.imgsz == IMGSZ
    x = torch.rand(3, 3, IMGSZ, IMGSZ)
    y = det.raw(x)
    assert y.shape[1] == 4 + 1 + 12 + 8
    plain, _ = load_pose_model(yolo26_pt, trust=True)
    y0 = plain.fuse()(x)[0]  # ultralytics' own inference: no σ
    assert y0.shape[1] == 4 + 1 + 12
    np.testing.assert_allclose(y[:, :17].numpy(), y0.numpy(), atol=1e-3)
    sig = split_sigma(y, 1)
    strides = det.model.head.strides[0]  # σ = sigmoid(raw) · stride: within (0, stride) per anchor
    assert sig.shape == (3, y.shape[2], 4, 2)
    assert (sig > 0).all() and (sig < strides[None, :, None, None]).all()
    assert split_sigma(y0, 1) is None
    with pytest.raises(ValueError, match="channels"):
        split_sigma(y[:, :20], 1)
    assert split_raw(y, 1)[2].shape == split_raw(y0, 1)[2].shape  # keypoints read alike from both layouts


def test_the_engines_carry_sigma_within_1e3_px(yolo26_pt, tmp_path, monkeypatch):
    from vbl_robust.detect.engines import installed_engines, with_engine
    from vbl_robust.detect.onnx import OnnxDetector
    from vbl_robust.detect.ultralytics import UltralyticsDetector

    monkeypatch.setenv("VBL_ROBUST_CACHE", str(tmp_path))
    det = UltralyticsDetector(yolo26_pt, trust=True)
    x = torch.rand(2, 3, IMGSZ, IMGSZ)
    y0 = det.raw(x)
    engines = [e for e in ("onnxruntime", "openvino") if e in installed_engines()]
    assert "onnxruntime" in engines
    for engine in engines:
        fast = with_engine(det, engine, trust=True)
        y = fast.engine_model.raw(x)
        assert y.shape == y0.shape, engine
        assert (y - y0).abs().max().item() < 1e-3, engine  # keypoints and σ alike
    onnx_files = list(tmp_path.rglob("*.onnx"))
    assert len(onnx_files) == 1 and OnnxDetector(onnx_files[0]).imgsz == IMGSZ  # metadata written


def test_detections_and_two_stage_carry_sigma_in_source_pixels(yolo26_pt):
    from vbl_robust.detect.shipped import default_detector
    from vbl_robust.detect.twostage import TwoStageDetector
    from vbl_robust.detect.ultralytics import UltralyticsDetector

    y26 = UltralyticsDetector(yolo26_pt, trust=True)
    sample = generate(1, seed=3)[0]
    obj = Objective(sample, y26, ParameterBox({"roll_deg": (-5.0, 5.0)}))
    ctx = obj.context(np.array([[0.0], [2.0]]))
    single = y26.detect(ctx)
    assert all(d.keypoint_sigma is not None and d.keypoint_sigma.shape == (len(d), 4, 2) for d in single)
    top = y26.top(ctx)  # σ of the max-confidence anchor, in source pixels: the view σ × (window side / view side)
    np.testing.assert_allclose(top.sigma.numpy(), np.stack([d.keypoint_sigma[0] for d in single]), rtol=1e-6)
    two = TwoStageDetector(default_detector().first, y26)
    t = two.top(ctx)
    win = two.crop_windows(default_detector().first.top(ctx).keypoints, ctx.height, ctx.width)
    views = ctx.views(win, IMGSZ)
    y = y26.raw(views)
    i = split_raw(y, 1)[1].argmax(1)
    expect = split_sigma(y, 1)[torch.arange(2), i] * (win[:, 2] / IMGSZ)[:, None, None]
    np.testing.assert_allclose(t.sigma.numpy(), expect.numpy(), rtol=1e-5)
    dets = two.detect(ctx)
    np.testing.assert_allclose(dets[1].keypoint_sigma[0], t.sigma[1].numpy(), rtol=1e-6)
    # the shipped v8 network says nothing: no σ anywhere
    assert default_detector().top(ctx).sigma is None and default_detector().detect(ctx)[0].keypoint_sigma is None


def test_select_keeps_the_selected_candidates_sigma():
    a = Detections(np.zeros((2, 4)), np.array([0.3, 0.9]), np.zeros((2, 4, 2)),
                   keypoint_sigma=np.stack([np.full((4, 2), 1.0), np.full((4, 2), 2.0)]))
    s = select([a, Detections(np.zeros((1, 4)), np.array([0.8]), np.zeros((1, 4, 2))), Detections.empty()])
    assert (s.sigma[0] == 2.0).all() and np.isnan(s.sigma[1:]).all()
    with pytest.raises(ValueError, match="keypoint_sigma"):
        Detections(np.zeros((1, 4)), np.array([0.8]), np.zeros((1, 4, 2)), keypoint_sigma=np.zeros(3))


def test_position_sigma_is_the_first_order_propagation_through_pnp():
    sample = generate(2, seed=5)[1]
    kp = np.asarray(sample.corners_2d, dtype=np.float64)[None]
    sig = np.array([[[0.5, 1.0], [2.0, 0.25], [1.0, 1.0], [0.1, 3.0]]])
    got = position_sigma(kp, sig, sample.corners_3d, sample.K)
    J = position_jacobian_fd(kp[0], sample.corners_3d, sample.K)  # (3, 8), metres per pixel
    expect = np.sqrt(((J * sig.reshape(1, 8)) ** 2).sum())
    assert got.shape == (1,) and got[0] == pytest.approx(expect, rel=1e-4)
    # doubling σ doubles it; a NaN σ or a degenerate row gives NaN, not a number
    assert position_sigma(kp, 2 * sig, sample.corners_3d, sample.K)[0] == pytest.approx(2 * got[0], rel=1e-9)
    bad = np.concatenate([kp, np.zeros((1, 4, 2))])
    out = position_sigma(bad, np.concatenate([sig, sig]), sample.corners_3d, sample.K)
    assert np.isfinite(out[0]) and np.isnan(out[1])
    assert np.isnan(position_sigma(kp, np.full((1, 4, 2), np.nan), sample.corners_3d, sample.K)[0])
    assert solve(kp, sample.corners_3d, sample.K).success[0]


class _SureOracle(OracleDetector):
    """The oracle's corners with a stated σ (pixels of the source): a detector that says how sure it is."""

    def __init__(self, sigma_px: float) -> None:
        super().__init__()
        self.sigma_px = sigma_px

    def detect(self, context):
        return [dataclasses.replace(d, keypoint_sigma=np.full((len(d), 4, 2), self.sigma_px))
                for d in super().detect(context)]


def test_the_sigma_monitor_turns_an_unsure_pose_into_a_flagged_failure():
    sample = generate(1, seed=7)[0]
    box = ParameterBox({"roll_deg": (-5.0, 5.0)})
    theta = np.array([[0.0], [3.0]])
    plain = Objective(sample, _SureOracle(0.5), box).evaluate(theta)
    assert plain.reason == ("", "") and np.all(plain.position_sigma_m > 0)
    assert plain.keypoint_sigma.shape == (2, 4, 2) and np.all(plain.keypoint_sigma == 0.5)
    assert "position_sigma_m" in plain.to_rows()[0]
    limit = float(plain.position_sigma_m.max()) * 1.01
    assert Objective(sample, _SureOracle(0.5), box, max_sigma_m=limit).evaluate(theta).reason == ("", "")
    # four times the corner σ: four times the position σ, above the limit → flagged, penalised
    rec = Objective(sample, _SureOracle(2.0), box, max_sigma_m=limit).evaluate(theta)
    assert rec.reason == ("monitor_rejected", "monitor_rejected") and np.all(rec.loss == rec.penalty_m)
    np.testing.assert_allclose(rec.position_sigma_m, 4 * plain.position_sigma_m, rtol=1e-6)
    # refused: a detector without σ, a gradient search, a bad limit
    with pytest.raises(ValueError, match="gives none"):
        Objective(sample, OracleDetector(), box, max_sigma_m=limit).evaluate(theta)
    assert Objective(sample, OracleDetector(), box).evaluate(theta).position_sigma_m is None
    with pytest.raises(ValueError, match="black-box path"):
        Objective(sample, _SureOracle(0.5), box, max_sigma_m=limit).evaluate(torch.zeros(1, 1))
    with pytest.raises(ValueError, match="max_sigma_m"):
        Objective(sample, _SureOracle(0.5), box, max_sigma_m=float("nan"))


def test_a_campaign_runs_the_sigma_monitor_and_stores_the_worst_candidates_sigma():
    from vbl_robust.campaigns.work import build_objective, worst_details
    from vbl_robust.specs.campaign import CampaignSpec
    from vbl_robust.specs.settings import PipelineSettings

    sample = generate(1, seed=7)[0]
    box = ParameterBox({"roll_deg": (-5.0, 5.0)})
    spec = CampaignSpec(name="s", blocks=(), settings=PipelineSettings(monitor_sigma_m=1e-6))
    assert CampaignSpec.from_dict(spec.to_dict()).settings.monitor_sigma_m == 1e-6  # kept in the stored spec (job context)
    assert spec.settings.to_dict()["monitor_sigma_m"] == 1e-6
    objective = build_objective(sample, _SureOracle(0.5), box, spec.settings)
    assert objective.evaluate(np.zeros((1, 1))).reason == ("monitor_rejected",)
    details, corners = worst_details(build_objective(sample, _SureOracle(0.5), box, PipelineSettings()),
                                     np.array([2.0]))
    assert corners is not None and details.corner_sigma_px == ((0.5, 0.5),) * 4
    assert details.position_sigma_m > 0 and details.to_json()["corner_sigma_px"] == [[0.5, 0.5]] * 4
    plain, _ = worst_details(build_objective(sample, OracleDetector(), box, PipelineSettings()),
                             np.array([2.0]))
    assert plain.corner_sigma_px is None and plain.position_sigma_m is None
    assert "corner_sigma_px" not in plain.to_json() and "position_sigma_m" not in plain.to_json()


@pytest.mark.parametrize("which", ["v9", "yolo26"])
def test_detect_and_top_map_only_what_they_keep_with_the_same_numbers(which, yolo26_pt):
    """The black-box path maps only the anchors NMS can keep, and ``top`` only the chosen one (issue 50): bit for
    bit what mapping every anchor (``candidates``) and then choosing gives."""
    import torchvision

    from vbl_robust.detect.shipped import default_detector
    from vbl_robust.detect.ultralytics import UltralyticsDetector

    det = default_detector().first if which == "v9" else UltralyticsDetector(yolo26_pt, trust=True)
    sample = generate(1, seed=11)[0]
    ctx = Objective(sample, det, ParameterBox({"roll_deg": (-15.0, 15.0)})).context(np.array([[0.0], [9.0], [-14.0]]))
    boxes, conf, kp, sig = det.candidates(ctx)
    with torch.no_grad():
        ref = det.top_of(boxes, conf, kp, sig)
        top = det.top(ctx)
    for a, b in ((ref.conf, top.conf), (ref.keypoints, top.keypoints), (ref.boxes, top.boxes), (ref.sigma, top.sigma)):
        assert (a is None and b is None) or torch.equal(a, b)
    got = det.detect(ctx)
    for b, d in enumerate(got):
        keep = torch.nonzero(conf[b] >= det.conf_min)[:, 0]
        if keep.numel() == 0:
            keep = conf[b].argmax()[None]
        sel = keep[torchvision.ops.nms(boxes[b, keep], conf[b, keep], det.iou)][:det.max_det]
        assert len(d) == len(sel) >= 1
        np.testing.assert_array_equal(d.boxes, boxes[b, sel].double().numpy())
        np.testing.assert_array_equal(d.keypoints, kp[b, sel].double().numpy())
        np.testing.assert_array_equal(d.conf, conf[b, sel].double().numpy())
        if sig is not None:
            np.testing.assert_array_equal(d.keypoint_sigma, sig[b, sel].double().numpy())
