"""The threshold-width loss term: its value, its gradient, its edges' mask, the criterion swap and a training run."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from detect_helpers import square_sample

from vbl_robust.detect import losses
from vbl_robust.detect.losses import edge_log_ratio, threshold_width_loss
from vbl_robust.detect.offline import import_ultralytics

# a runway's corners TR, TL, BL, BR in pixels: far edge 20 px wide, near edge 60 px wide
TRUE = torch.tensor([[[110.0, 40.0], [90.0, 40.0], [70.0, 100.0], [130.0, 100.0]]])


def _scaled_edges(c: torch.Tensor, far: float, near: float) -> torch.Tensor:
    """Each threshold edge scaled about its midpoint."""
    out = c.clone()
    for (a, b), f in zip(losses.THRESHOLD_EDGES, (far, near), strict=True):
        mid = (c[:, a] + c[:, b]) / 2
        out[:, a], out[:, b] = mid + f * (c[:, a] - mid), mid + f * (c[:, b] - mid)
    return out


def test_edge_log_ratio_is_the_log_of_the_width_ratio():
    vis = torch.ones(1, 4, dtype=torch.bool)
    vals, ok = edge_log_ratio(TRUE, TRUE, vis, min_px=8.0)
    assert ok.all() and torch.allclose(vals, torch.zeros(1, 2))
    vals, ok = edge_log_ratio(_scaled_edges(TRUE, 1.1, 0.8), TRUE, vis, min_px=8.0)
    assert vals[0].tolist() == pytest.approx([math.log(1.1), -math.log(0.8)], rel=1e-5)
    # translating the whole runway changes no width
    vals, _ = edge_log_ratio(TRUE + torch.tensor([5.0, -3.0]), TRUE, vis, min_px=8.0)
    assert torch.allclose(vals, torch.zeros(1, 2), atol=1e-6)


def test_edge_mask_leaves_out_narrow_and_hidden_edges():
    vis = torch.ones(1, 4, dtype=torch.bool)
    _, ok = edge_log_ratio(TRUE, TRUE, vis, min_px=30.0)  # far edge 20 px < 30: out; near 60 px: in
    assert ok[0].tolist() == [False, True]
    vis[0, 2] = False  # BL hidden: the near edge is out too
    _, ok = edge_log_ratio(TRUE, TRUE, vis, min_px=0.0)
    assert ok[0].tolist() == [True, False]


def _criteria(gain: float, min_px: float, base: str = "v8PoseLoss"):
    import_ultralytics()
    from ultralytics.utils import loss as ul

    out = []
    for cls in (getattr(ul, base), losses._pose_loss_class(gain, min_px, getattr(ul, base))):
        c = cls.__new__(cls)  # no model: only what calculate_keypoints_loss reads
        c.keypoint_loss = ul.KeypointLoss(sigmas=torch.ones(4) / 4)
        c.bce_pose = torch.nn.BCEWithLogitsLoss()
        c.rle_loss = None  # YOLO26's criterion: its residual log-likelihood term is its own, untouched here
        out.append(c)
    return out


def _keypoint_inputs(pred_px: torch.Tensor, stride: float = 8.0):
    """One image, three anchors, the first two assigned to the one runway (pixels → the criterion's units)."""
    masks = torch.tensor([[True, True, False]])
    target_gt_idx = torch.zeros(1, 3, dtype=torch.long)
    keypoints = torch.cat([TRUE, torch.full((1, 4, 1), 2.0)], -1)[:, None]  # (1, 1, 4, 3)
    stride_tensor = torch.full((3, 1), stride)
    bboxes = torch.tensor([[[70.0, 40.0, 130.0, 100.0]]]).expand(1, 3, 4).clone()
    pred = torch.cat([pred_px / stride, torch.zeros(1, 4, 1)], -1)[:, None].expand(1, 3, 4, 3).clone()
    return masks, target_gt_idx, keypoints, stride_tensor, bboxes, pred.requires_grad_(True)


@pytest.mark.parametrize("criterion", ["v8PoseLoss", "PoseLoss26"])
def test_criterion_adds_gain_times_the_mean_log_width_error(criterion):
    base, withw = _criteria(gain=0.5, min_px=8.0, base=criterion)
    pred_px = _scaled_edges(TRUE, 1.1, 0.8)
    base_inputs, inputs = _keypoint_inputs(pred_px), _keypoint_inputs(pred_px)
    a = base.calculate_keypoints_loss(*base_inputs)[0]
    b = withw.calculate_keypoints_loss(*inputs)[0]
    expect = 0.5 * (math.log(1.1) - math.log(0.8)) / 2
    assert float((b - a).detach()) == pytest.approx(expect, rel=1e-5)
    a.backward()
    b.backward()
    g = (inputs[-1].grad - base_inputs[-1].grad)[0, 0, :, :2]  # the term's own gradient
    # it pulls the too-wide far edge's corners together and the too-narrow near edge's apart, along the edges
    assert torch.allclose(g[:, 1], torch.zeros(4), atol=1e-7)
    assert float(g[0, 0]) > 0 > float(g[1, 0])  # TR (right) moves left, TL (left) moves right
    assert float(g[2, 0]) > 0 > float(g[3, 0])  # BL moves left, BR moves right
    # edges narrower than min_px leave ultralytics' loss unchanged
    _, strict = _criteria(gain=0.5, min_px=100.0, base=criterion)
    c = strict.calculate_keypoints_loss(*_keypoint_inputs(pred_px))[0]
    assert float(c.detach()) == pytest.approx(float(a.detach()), rel=1e-7)


def test_context_swaps_the_pose_criterion_and_restores_it():
    import_ultralytics()
    from ultralytics.nn import tasks

    before, before26 = tasks.v8PoseLoss, tasks.PoseLoss26
    with threshold_width_loss(0.0):
        assert tasks.v8PoseLoss is before and tasks.PoseLoss26 is before26
    with pytest.raises(RuntimeError, match="boom"), threshold_width_loss(0.3, 4.0):
        assert issubclass(tasks.v8PoseLoss, before) and tasks.v8PoseLoss is not before
        assert issubclass(tasks.PoseLoss26, before26) and tasks.PoseLoss26 is not before26
        assert tasks.v8PoseLoss.width_gain == 0.3 and tasks.v8PoseLoss.width_min_px == 4.0
        assert tasks.PoseLoss26.width_gain == 0.3
        raise RuntimeError("boom")
    assert tasks.v8PoseLoss is before and tasks.PoseLoss26 is before26
    with pytest.raises(ValueError, match="gain"), threshold_width_loss(-1.0):
        pass


def test_training_run_uses_the_width_term(tmp_path, monkeypatch):
    from vbl_robust.detect.train import train

    calls = []
    real = losses.edge_log_ratio

    def spy(*a, **k):
        out = real(*a, **k)
        calls.append(int(out[1].sum()))
        return out

    monkeypatch.setattr(losses, "edge_log_ratio", spy)
    r = train(tmp_path / "run", samples=[square_sample(i, 96) for i in range(6)], n_val=2, imgsz=64, epochs=1,
              batch=4, workers=0, seed=0, width_loss=0.5, width_loss_min_px=0.0)
    assert r.last.exists()
    assert calls and np.sum(calls) > 0  # the criterion of the run computed the term on labelled edges
