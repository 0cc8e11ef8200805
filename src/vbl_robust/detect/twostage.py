"""Two-stage runway-corner detector: locate on the whole image, then refine the corners on a crop.

Pass 1 runs a pose network on the letterboxed image and keeps the max-confidence candidate (this is where the
confidence threshold of the selection applies). Pass 2 resamples a square crop around that candidate's corner
box (:func:`~vbl_robust.detect.views.box_window`: ``margin`` × the box, at least ``min_side`` image pixels) to the
network's input size and runs a pose network on it; its max-confidence keypoints, mapped back to image pixels,
are the output. Both passes are differentiable (``grid_sample`` crop), and by default share one network trained
on full views and jittered crops (:mod:`vbl_robust.detect.train`).

``input_size`` is None: the crop needs the full-resolution image, so the pipeline must not downsample first.
Instead of perturbing the full-resolution image and then sampling two small views of it, the detector can
sample its views of the perturbed image directly from the unperturbed one (roll and contrast folded into the
sampling grid, :func:`~vbl_robust.detect.views.perturbed_resample`): :meth:`applies_perturbation` tells the
objective to hand it the unperturbed image with a :class:`~vbl_robust.detect.DetectContext` whose
``perturbed`` is False. That removes the full-resolution warp from every evaluation (one interpolation instead of
two; the views agree to interpolation smoothing — tested on images and on keypoints).
"""

from __future__ import annotations

import torch

from .base import DetectContext, Detections
from .ultralytics import PoseDetector, Top, split_raw
from .views import (
    box_window,
    letterbox_window,
    perturbed_resample,
    pool_factor,
    pooled_source,
    resample,
    rolled_gray_mean,
    to_tensor,
    view_to_image,
)

#: perturbations a two-stage detector can fold into its view sampling
FUSABLE = frozenset({"roll_deg", "contrast"})


class TwoStageDetector(PoseDetector):
    """Detect → crop → keypoints.

    Args:
        first: pass-1 detector (any :class:`~vbl_robust.detect.ultralytics.PoseDetector`).
        second: pass-2 detector (default: ``first``).
        margin, min_side: crop window around the pass-1 corner box (must match training, see
            :class:`~vbl_robust.detect.train.CropJitter`).
        refine: number of crop passes (2: crop again around the first crop's corners).
        fuse: sample the views of the perturbed image from the unperturbed one when the objective allows it
            (:meth:`applies_perturbation`); False → the objective perturbs the full image first.
    """

    def __init__(self, first: PoseDetector, second: PoseDetector | None = None, *, margin: float = 1.5,
                 min_side: float = 64.0, refine: int = 1, fuse: bool = True) -> None:
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
        self.fuse = bool(fuse)

    def applies_perturbation(self, perturbation) -> bool:
        """True if this detector can apply ``perturbation`` itself while sampling its views (roll, contrast)."""
        return self.fuse and set(perturbation.names) <= FUSABLE

    def crop_windows(self, first_kpts: torch.Tensor, height: int, width: int) -> torch.Tensor:
        """(B, 3) crop windows around pass-1 keypoints (B, 4, 2) (OpenCV px)."""
        e = first_kpts + 0.5
        box = torch.cat([e.amin(1), e.amax(1)], 1)
        return box_window(box, margin=self.margin, min_side=self.min_side, max_side=2.0 * max(height, width))

    def top(self, images, context: DetectContext | None = None) -> Top:
        """Differentiable: pass-1 max-confidence conf and box, pass-2 keypoints (image px, OpenCV).

        With a ``context`` whose ``perturbed`` is False, ``images`` are the unperturbed image (one row, or the
        same row broadcast) and the views are sampled from it with ``context.theta`` applied.
        """
        x = to_tensor(images)
        if context is None or context.perturbed:
            t1 = self.first.top(x)

            def views(win, size):
                return resample(x, win, size)
        else:
            t1, views = self._fused(x, context)
        kp = t1.keypoints
        s2 = self.second
        for _ in range(self.refine):
            win = self.crop_windows(kp, *x.shape[-2:])
            _, conf2, k2 = split_raw(s2.raw_chunked(views(win, s2.imgsz)), s2.nc)
            i = conf2.argmax(1)
            k = k2.gather(1, i[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
            kp = view_to_image(k, win, s2.imgsz)
        return Top(t1.conf, kp, t1.boxes)

    def _fused(self, x: torch.Tensor, context: DetectContext):
        """Pass 1 on views of the perturbed image sampled from the unperturbed ``x``; returns (Top, view sampler)."""
        if not self.applies_perturbation(context.perturbation):
            raise ValueError(f"TwoStageDetector: cannot apply perturbations {context.perturbation.names} itself; "
                             "give it perturbed images (DetectContext.perturbed=True)")
        theta = context.theta
        th = theta if isinstance(theta, torch.Tensor) else torch.as_tensor(theta, dtype=torch.float64)
        b = th.shape[0]
        src = x[:1] if (x.shape[0] == 1 or x.stride(0) == 0) else x
        if src.shape[0] not in (1, b):
            raise ValueError(f"TwoStageDetector: {x.shape[0]} images for {b} parameter rows")
        angle = context.perturbation.column(th, "roll_deg")
        factor = context.perturbation.column(th, "contrast")
        center = torch.as_tensor(context.center, dtype=x.dtype)
        h, w = x.shape[-2:]
        win1 = torch.tensor(letterbox_window(h, w), dtype=x.dtype).expand(b, 3)
        p1 = pool_factor(float(win1[0, 2]), self.first.imgsz)
        pooled: dict[int, torch.Tensor] = {}
        gray = rolled_gray_mean(pooled_source(src, p1, pooled), p1, h, w, angle, center)

        def views(win, size):
            return perturbed_resample(src, win, size, angle_deg=angle, center=center, contrast=factor,
                                      gray_mean=gray, pooled=pooled)

        f = self.first
        return f.top_of(*f.candidates_in_views(views(win1, f.imgsz), win1)), views

    def detect_top(self, images, *, context: DetectContext | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Protocol form of :meth:`top`: ``(conf (B,), keypoints (B, 4, 2))``, differentiable."""
        t = self.top(images, context)
        return t.conf, t.keypoints

    @torch.no_grad()
    def detect(self, images, *, context: DetectContext | None = None, conf_min: float = 0.01, iou: float = 0.7,
               max_det: int = 10) -> list[Detections]:
        """Black box: one candidate per image (the refined max-confidence one)."""
        t = self.top(images, context)
        return [Detections(t.boxes[b:b + 1], t.conf[b:b + 1], t.keypoints[b:b + 1]) for b in range(t.conf.shape[0])]
