"""A training loss term on the runway's threshold widths, added to ultralytics' YOLOv8-Pose (and YOLO26-pose)
keypoint loss.

Why: at far range the camera position from PnP is decided by the two threshold edges' widths in the image (the
slant distance scales with 1 / width); with the true near-threshold width, far survival on the validation set
would be 96.8 % instead of 87.1 % (model card, *What decides far survival*). Ultralytics' keypoint loss is an OKS, the
squared corner distance divided by the box area, applied to each corner on its own: it does not see that a 0.5 px
error of both near corners in opposite directions is a 7 % width error of a far runway, and its gradient vanishes
as the error shrinks (quadratic near zero).

The term, for each labelled runway (a positive anchor) whose threshold edge is at least ``min_px`` pixels wide in
the training view, with both corners of that edge visible::

    gain · | log(w_pred / w_true) |        w = ‖corner_a − corner_b‖ (pixels) of the edge TL–TR or BL–BR

averaged over edges and instances, added to the keypoint loss before ultralytics multiplies it by its ``pose``
gain. It is relative (the same weight at every range) and L1 (a constant push toward the exact width). ``min_px``
keeps out the full views of far runways (3–7 px wide at 320 px), whose widths the two-stage detector never uses:
it reads the corners off the magnified crop.

Written by hand: ultralytics has no hook for an extra keypoint term, so :func:`threshold_width_loss` swaps its
pose criterion class for :class:`ThresholdWidthPoseLoss` (a subclass) while a training run builds its model.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch

#: corner pairs (a, b) of the two threshold edges in the keypoint order TR, TL, BL, BR
THRESHOLD_EDGES = ((0, 1), (3, 2))


def edge_log_ratio(pred: torch.Tensor, true: torch.Tensor, visible: torch.Tensor, *, min_px: float) -> torch.Tensor:
    """|log(w_pred / w_true)| of the threshold edges: (n, 4, 2) pixel corners, (n, 4) visibility → (n, 2) values
    and a (n, 2) mask of the edges that count (both corners visible, true width ≥ ``min_px``)."""
    vals, masks = [], []
    for a, b in THRESHOLD_EDGES:
        w_true = (true[:, a] - true[:, b]).norm(dim=-1)
        w_pred = (pred[:, a] - pred[:, b]).norm(dim=-1)
        ok = visible[:, a] & visible[:, b] & (w_true >= min_px)
        vals.append((torch.log(w_pred.clamp_min(1e-3)) - torch.log(w_true.clamp_min(1e-3))).abs())
        masks.append(ok)
    return torch.stack(vals, 1), torch.stack(masks, 1)


def _pose_loss_class(gain: float, min_px: float, base: type | None = None):
    """``base`` (ultralytics' v8 pose criterion by default; YOLO26's ``PoseLoss26`` too) with the threshold-width
    term added to its keypoint loss (the first value its ``calculate_keypoints_loss`` returns)."""
    if base is None:
        from ultralytics.utils.loss import v8PoseLoss as base

    class ThresholdWidthPoseLoss(base):
        """Ultralytics' pose criterion plus the threshold-width term of this module (``gain``, ``min_px``)."""

        width_gain = float(gain)
        width_min_px = float(min_px)

        def calculate_keypoints_loss(self, masks, target_gt_idx, keypoints, stride_tensor, target_bboxes,
                                     pred_kpts):
            kpts_loss, *rest = super().calculate_keypoints_loss(
                masks, target_gt_idx, keypoints, stride_tensor, target_bboxes, pred_kpts)
            if self.width_gain and masks.any():
                gt = keypoints[masks.nonzero(as_tuple=True)[0], target_gt_idx[masks]]  # (n, 4, 3) pixels
                stride = stride_tensor.view(1, -1).expand(masks.shape[0], -1)[masks][:, None, None]
                pred = pred_kpts[masks][..., :2] * stride  # feature-grid units → pixels
                vals, ok = edge_log_ratio(pred, gt[..., :2], gt[..., 2] != 0, min_px=self.width_min_px)
                if ok.any():
                    kpts_loss = kpts_loss + self.width_gain * vals[ok].mean()
            return (kpts_loss, *rest)

    ThresholdWidthPoseLoss.__name__ = f"ThresholdWidth{base.__name__}"
    return ThresholdWidthPoseLoss


@contextlib.contextmanager
def threshold_width_loss(gain: float, min_px: float = 8.0) -> Iterator[None]:
    """Within this context, YOLOv8-Pose and YOLO26-pose models built by ultralytics train with the threshold-width
    term (on YOLO26 it joins the keypoint loss beside the residual log-likelihood term).

    ``gain`` 0 leaves ultralytics' loss as it is. The swap is undone on exit (also on an exception)."""
    if gain < 0 or min_px < 0:
        raise ValueError(f"threshold_width_loss: gain and min_px must be ≥ 0, got {gain!r}, {min_px!r}")
    from ultralytics.nn import tasks

    before = tasks.v8PoseLoss, tasks.PoseLoss26
    if gain:
        tasks.v8PoseLoss = _pose_loss_class(gain, min_px, before[0])
        tasks.PoseLoss26 = _pose_loss_class(gain, min_px, before[1])
    try:
        yield
    finally:
        tasks.v8PoseLoss, tasks.PoseLoss26 = before
