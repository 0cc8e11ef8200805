"""Two-stage runway-corner detector: locate on the whole image, then refine the corners on a crop.

Pass 1 runs a pose model on the letterboxed image and keeps the max-confidence candidate (this is where the
confidence threshold of the selection applies). Pass 2 asks for a square crop around that candidate's corner box
(:func:`~vbl_robust.detect.windows.box_window`: ``margin`` × the box, at least ``min_side`` image pixels) at the
model's input size and runs a pose model on it; its max-confidence keypoints, mapped back to image pixels, are
the output. By default both passes are one network trained on full views and jittered crops
(:mod:`vbl_robust.detect.train`).

The detector composes two :class:`~vbl_robust.detect.pose.PoseDetector` and never touches a perturbation: both
passes ask the context's view sampler for their windows (:mod:`vbl_robust.perturb.views`), which samples the
perturbed views straight from the unperturbed full-resolution image — hence ``input_size = None``: the crop
needs the source at full resolution. Both passes are differentiable.
"""

from __future__ import annotations

import torch

from vbl_robust.perturb.views import view_to_image

from .base import Detections, as_context
from .pose import PoseDetector, Top, sigma_to_image, split_raw, split_sigma
from .windows import box_window, corner_box

__all__ = ["TwoStageDetector"]


class TwoStageDetector:
    """Detect → crop → keypoints.

    Args:
        first: pass-1 pose model (any :class:`~vbl_robust.detect.pose.PoseDetector`).
        second: pass-2 pose model (default: ``first``).
        margin, min_side: crop window around the pass-1 corner box (must match training, see
            :class:`~vbl_robust.detect.train.CropJitter`).
        refine: number of crop passes (2: crop again around the first crop's corners).

    The black-box path returns one candidate per image (the refined max-confidence one); NMS does not apply.
    """

    input_size: int | None = None
    uses_pixels: bool = True

    def __init__(self, first: PoseDetector, second: PoseDetector | None = None, *, margin: float = 1.5,
                 min_side: float = 64.0, refine: int = 1) -> None:
        if refine < 1:
            raise ValueError(f"TwoStageDetector: refine must be >= 1, got {refine}")
        self.refine = int(refine)
        self.first = first
        self.second = second or first
        self.margin, self.min_side = float(margin), float(min_side)
        #: the corners' σ comes from pass 2 (the network that places them)
        self.gives_sigma = bool(self.second.gives_sigma)

    def __repr__(self) -> str:
        second = "" if self.second is self.first else f", second={self.second!r}"
        return f"TwoStageDetector({self.first!r}{second}, margin={self.margin}, min_side={self.min_side})"

    @property
    def differentiable(self) -> bool:
        """Both passes have the differentiable path (read each time: an ONNX twin can lose it on its first check)."""
        return bool(self.first.differentiable and self.second.differentiable)

    @property
    def gradient_unavailable(self) -> str:
        """Why the differentiable path is unavailable (``""`` when it is): the first pass's reason, else the
        second's."""
        if self.differentiable:
            return ""
        return (getattr(self.first, "gradient_unavailable", "") or getattr(self.second, "gradient_unavailable", "")
                or "a pass of the two-stage detector is not differentiable")

    @property
    def device(self):
        """The first pass's device (where :class:`vbl_robust.Objective` makes the views)."""
        return getattr(self.first, "device", "cpu")

    @property
    def imgsz(self) -> int:
        return self.first.imgsz

    def crop_windows(self, first_kpts: torch.Tensor, height: int, width: int) -> torch.Tensor:
        """(B, 3) crop windows around pass-1 keypoints (B, 4, 2) (OpenCV px)."""
        return box_window(corner_box(first_kpts), margin=self.margin, min_side=self.min_side,
                          max_side=2.0 * max(height, width))

    def top(self, context) -> Top:
        """Differentiable: pass-1 max-confidence conf and box, pass-2 keypoints (source px, OpenCV) and, when the
        pass-2 network has an uncertainty head, their σ (source px)."""
        ctx = as_context(context)
        t1 = self.first.top(ctx)
        kp, s2, sigma = t1.keypoints, self.second, None
        for _ in range(self.refine):
            win = self.crop_windows(kp, ctx.height, ctx.width)
            y = s2.raw_chunked(ctx.views(win, s2.imgsz))
            _, conf2, k2 = split_raw(y, s2.nc)
            i = conf2.argmax(1)[:, None, None, None].expand(-1, 1, 4, 2)
            kp = view_to_image(k2.gather(1, i)[:, 0], win, s2.imgsz)
            sig = split_sigma(y, s2.nc)
            sigma = None if sig is None else sigma_to_image(sig.gather(1, i)[:, 0], win, s2.imgsz)
        return Top(t1.conf, kp, t1.boxes, sigma)

    def detect_top(self, context) -> tuple[torch.Tensor, torch.Tensor]:
        """Protocol form of :meth:`top`: ``(conf (B,), keypoints (B, 4, 2))``, differentiable."""
        t = self.top(context)
        return t.conf, t.keypoints

    @torch.no_grad()
    def detect(self, context) -> list[Detections]:
        """Black box: one candidate per image (the refined max-confidence one)."""
        t = self.top(context)
        return [Detections(t.boxes[b:b + 1], t.conf[b:b + 1], t.keypoints[b:b + 1],
                           keypoint_sigma=None if t.sigma is None else t.sigma[b:b + 1])
                for b in range(t.conf.shape[0])]

