"""Two-stage runway-corner detector: locate on the whole image, then refine the corners on a crop.

Pass 1 runs a pose network on the letterboxed image and keeps the max-confidence candidate (this is where the
confidence threshold of the selection applies). Pass 2 resamples a square crop around that candidate's corner
box (:func:`~vbl_robust.detect.views.box_window`: ``margin`` × the box, at least ``min_side`` image pixels) to the
network's input size and runs a pose network on it; its max-confidence keypoints, mapped back to image pixels,
are the output. Both passes are differentiable (``grid_sample`` crop), and by default share one network trained
on full views and jittered crops (:mod:`vbl_robust.detect.train`).

``input_size`` is None: the crop needs the full-resolution image, so the pipeline must not downsample first.
"""

from __future__ import annotations

import torch

from .base import DetectContext, Detections
from .ultralytics import PoseDetector, Top, split_raw
from .views import box_window, resample, to_tensor, view_to_image


class TwoStageDetector(PoseDetector):
    """Detect → crop → keypoints.

    Args:
        first: pass-1 detector (any :class:`~vbl_robust.detect.ultralytics.PoseDetector`).
        second: pass-2 detector (default: ``first``).
        margin, min_side: crop window around the pass-1 corner box (must match training, see
            :class:`~vbl_robust.detect.train.CropJitter`).
        refine: number of crop passes (2: crop again around the first crop's corners).
    """

    def __init__(self, first: PoseDetector, second: PoseDetector | None = None, *, margin: float = 1.5,
                 min_side: float = 64.0, refine: int = 1) -> None:
        if refine < 1:
            raise ValueError(f"TwoStageDetector: refine must be >= 1, got {refine}")
        self.refine = int(refine)
        self.first = first
        self.second = second or first
        self.margin, self.min_side = float(margin), float(min_side)
        self.imgsz = self.first.imgsz
        self.input_size = None
        self.chunk = self.first.chunk
        self.differentiable = self.first.differentiable and self.second.differentiable

    def crop_windows(self, first_kpts: torch.Tensor, height: int, width: int) -> torch.Tensor:
        """(B, 3) crop windows around pass-1 keypoints (B, 4, 2) (OpenCV px)."""
        e = first_kpts + 0.5
        box = torch.cat([e.amin(1), e.amax(1)], 1)
        return box_window(box, margin=self.margin, min_side=self.min_side, max_side=2.0 * max(height, width))

    def top(self, images) -> Top:
        """Differentiable: pass-1 max-confidence conf and box, pass-2 keypoints (image px, OpenCV)."""
        x = to_tensor(images)
        t1 = self.first.top(x)
        kp = t1.keypoints
        s2 = self.second
        for _ in range(self.refine):
            win = self.crop_windows(kp, *x.shape[-2:])
            views = resample(x, win, s2.imgsz)
            _, conf2, k2 = split_raw(s2.raw_chunked(views), s2.nc)
            i = conf2.argmax(1)
            k = k2.gather(1, i[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
            kp = view_to_image(k, win, s2.imgsz)
        return Top(t1.conf, kp, t1.boxes)

    @torch.no_grad()
    def detect(self, images, *, context: DetectContext | None = None, conf_min: float = 0.01, iou: float = 0.7,
               max_det: int = 10) -> list[Detections]:
        """Black box: one candidate per image (the refined max-confidence one)."""
        t = self.top(images)
        return [Detections(t.boxes[b:b + 1], t.conf[b:b + 1], t.keypoints[b:b + 1]) for b in range(t.conf.shape[0])]
