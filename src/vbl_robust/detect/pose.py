"""The pose-model detector base: a YOLO-pose network on square views, and its two paths.

A :class:`PoseDetector` wraps a network that maps views ``(B, 3, S, S)`` in [0, 1] to raw predictions
``y (B, 4 + nc + K·3, A)`` (ultralytics' layout, before NMS; subclasses implement :meth:`PoseDetector.raw`:
``.pt`` in :mod:`.ultralytics`, ONNX in :mod:`.onnx`). A network with a keypoint-uncertainty head (YOLO26-pose)
appends ``K·2`` channels: each corner's σ_x, σ_y in view pixels (:func:`split_sigma`); the layout tells, so every
engine of such a network carries them. As a detector it is the paper's single pass: it asks the
context for the letterboxed view of each perturbed image and reads the candidates back in source pixels
(OpenCV convention), keypoints TR, TL, BL, BR.

- :meth:`PoseDetector.detect` — black box: ``no_grad``, NMS (``conf_min``, ``iou``, ``max_det``);
  :class:`~vbl_robust.detect.base.Detections` per image, highest confidence first.
- :meth:`PoseDetector.detect_top` / :meth:`PoseDetector.top` — differentiable: the anchor of maximum
  confidence (``argmax`` + ``gather``). NMS always keeps the global maximum, so it equals the black box's top.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from vbl_robust.perturb.views import view_to_image

from .base import DetectContext, Detections, as_context
from .windows import letterbox_window

__all__ = ["PoseDetector", "Top", "split_raw", "split_sigma"]


@dataclass
class Top:
    """Max-confidence candidate per image (differentiable): conf (B,), keypoints (B, 4, 2), boxes (B, 4), and the
    keypoints' σ (B, 4, 2) in the same pixels when the network has an uncertainty head (else None)."""

    conf: torch.Tensor
    keypoints: torch.Tensor
    boxes: torch.Tensor
    sigma: torch.Tensor | None = None


def split_raw(y: torch.Tensor, nc: int, nk: int = 4, kdim: int = 3) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Raw predictions (B, 4 + nc + nk·kdim, A) → (boxes xyxy (B, A, 4), conf (B, A), keypoints (B, A, nk, 2)).

    Coordinates stay in view-pixel edge coordinates (ultralytics' convention).
    """
    y = y.transpose(1, 2)
    xy, wh = y[..., :2], y[..., 2:4]
    boxes = torch.cat([xy - wh / 2, xy + wh / 2], -1)
    conf = y[..., 4:4 + nc].amax(-1) if nc > 1 else y[..., 4]
    k = y[..., 4 + nc:4 + nc + nk * kdim].reshape(*y.shape[:2], nk, kdim)[..., :2]
    return boxes, conf, k


def split_sigma(y: torch.Tensor, nc: int, nk: int = 4, kdim: int = 3) -> torch.Tensor | None:
    """Raw predictions → the keypoints' σ ``(B, A, nk, 2)`` in view pixels, or None when the layout has no σ
    channels (``4 + nc + nk·kdim`` channels: a network without an uncertainty head).

    Raises:
        ValueError: a channel count that is neither layout.
    """
    base = 4 + nc + nk * kdim
    if y.shape[1] == base:
        return None
    if y.shape[1] != base + 2 * nk:
        raise ValueError(f"raw pose predictions have {y.shape[1]} channels; expected {base} (keypoints) or "
                         f"{base + 2 * nk} (keypoints and their σ) for {nc} class(es) and {nk} keypoints")
    return y[:, base:].transpose(1, 2).reshape(y.shape[0], y.shape[2], nk, 2)


def sigma_to_image(sigma: torch.Tensor, windows: torch.Tensor, size: int) -> torch.Tensor:
    """σ in view pixels (B, ..., 2) → image pixels: scaled by the window's side over the view's (no shift)."""
    side = torch.as_tensor(windows, dtype=sigma.dtype, device=sigma.device)[:, 2]
    return sigma * (side / size).reshape(-1, *([1] * (sigma.ndim - 1)))


class PoseDetector:
    """A pose network as a single-pass runway-corner detector; subclasses implement :meth:`raw`.

    Attributes: ``imgsz`` (view side), ``nc`` (classes), ``chunk`` (views per forward pass), NMS settings
    ``conf_min``, ``iou``, ``max_det`` of the black-box path; ``input_size = imgsz`` (the objective hands over a
    source already at that size).
    """

    imgsz: int
    nc: int = 1
    input_size: int | None
    chunk: int = 16
    uses_pixels: bool = True
    differentiable: bool = True
    #: why the differentiable path is unavailable (``""`` when ``differentiable``; one line, read when a gradient
    #: search is refused: :func:`vbl_robust.detect.onnx_twin.gradient_refusal`)
    gradient_unavailable: str = ""
    #: the raw output carries each corner's σ (a network with an uncertainty head; set by the subclass on loading)
    gives_sigma: bool = False
    conf_min: float = 0.01
    iou: float = 0.7
    max_det: int = 10

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        """Network on views (B, 3, imgsz, imgsz) in [0, 1] → raw predictions (B, 4 + nc + 12, A)."""
        raise NotImplementedError

    def raw_chunked(self, views: torch.Tensor) -> torch.Tensor:
        """:meth:`raw` in chunks of ``chunk`` views (bounds memory)."""
        if views.shape[0] <= self.chunk:
            return self.raw(views)
        return torch.cat([self.raw(v) for v in views.split(self.chunk)], 0)

    def candidates_in_views(self, views: torch.Tensor, win: torch.Tensor):
        """All anchors of views sampled at windows ``win`` (B, 3): boxes (B, A, 4), conf (B, A), keypoints
        (B, A, 4, 2), in source pixels (OpenCV), and the keypoints' σ (B, A, 4, 2) in source pixels (None for a
        network without an uncertainty head)."""
        y = self.raw_chunked(views)
        boxes, conf, k = split_raw(y, self.nc)
        b, a = conf.shape
        kp = view_to_image(k.reshape(b, a * 4, 2), win, self.imgsz).reshape(b, a, 4, 2)
        bx = view_to_image(boxes.reshape(b, a * 2, 2), win, self.imgsz).reshape(b, a, 4)
        sig = split_sigma(y, self.nc)
        return bx, conf, kp, (None if sig is None else sigma_to_image(sig, win, self.imgsz))

    def letterbox(self, context: DetectContext) -> tuple[torch.Tensor, torch.Tensor]:
        """``(views, windows)`` of the letterboxed perturbed images at ``imgsz``."""
        win = torch.tensor(letterbox_window(context.height, context.width), dtype=torch.float32,
                           device=context.device)
        win = win.expand(len(context), 3)
        return context.views(win, self.imgsz), win

    def candidates(self, context) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """All anchors on the letterboxed images of a context (or of plain images): :meth:`candidates_in_views`."""
        return self.candidates_in_views(*self.letterbox(as_context(context)))

    def top(self, context) -> Top:
        """Differentiable max-confidence candidate per image of a context (or of plain images): the anchor is
        chosen in view coordinates and only it is mapped to the source (the same numbers as mapping every anchor,
        :meth:`candidates`, then choosing: the map is elementwise)."""
        views, win = self.letterbox(as_context(context))
        y = self.raw_chunked(views)
        boxes, conf, k = split_raw(y, self.nc)
        sig = split_sigma(y, self.nc)
        t = self.top_of(boxes, conf, k, sig)
        n = conf.shape[0]
        return Top(t.conf, view_to_image(t.keypoints, win, self.imgsz),
                   view_to_image(t.boxes.reshape(n, 2, 2), win, self.imgsz).reshape(n, 4),
                   None if sig is None else sigma_to_image(t.sigma, win, self.imgsz))

    @staticmethod
    def top_of(boxes: torch.Tensor, conf: torch.Tensor, kp: torch.Tensor, sigma: torch.Tensor | None = None) -> Top:
        """The max-confidence anchor of candidates (``gather``, differentiable)."""
        i = conf.argmax(dim=1)
        c = conf.gather(1, i[:, None])[:, 0]
        k = kp.gather(1, i[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
        bx = boxes.gather(1, i[:, None, None].expand(-1, 1, 4))[:, 0]
        sig = None if sigma is None else sigma.gather(1, i[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
        return Top(c, k, bx, sig)

    def detect_top(self, context) -> tuple[torch.Tensor, torch.Tensor]:
        """Protocol form of :meth:`top`: ``(conf (B,), keypoints (B, 4, 2))``, differentiable."""
        t = self.top(context)
        return t.conf, t.keypoints

    @torch.no_grad()
    def detect(self, context) -> list[Detections]:
        """Black-box path: candidates after NMS per image, highest confidence first."""
        import torchvision

        views, win = self.letterbox(as_context(context))
        y = self.raw_chunked(views)
        boxes, conf, k = split_raw(y, self.nc)
        sig = split_sigma(y, self.nc)
        # only the anchors NMS can keep are mapped to the source (the map is elementwise: the same numbers)
        keep = conf >= self.conf_min
        keep[torch.arange(conf.shape[0]), conf.argmax(1)] |= ~keep.any(1)  # the maximum is always a candidate
        rows, anchors = torch.nonzero(keep, as_tuple=True)
        w = win[rows]
        bx = view_to_image(boxes[rows, anchors].reshape(-1, 2, 2), w, self.imgsz).reshape(-1, 4)
        kp = view_to_image(k[rows, anchors], w, self.imgsz)
        sg = None if sig is None else sigma_to_image(sig[rows, anchors], w, self.imgsz)
        cf = conf[rows, anchors]
        out, start = [], 0
        for count in torch.bincount(rows, minlength=conf.shape[0]).tolist():
            part = slice(start, start + count)
            start += count
            sel = torchvision.ops.nms(bx[part], cf[part], self.iou)[:self.max_det] + part.start
            out.append(Detections(bx[sel], cf[sel], kp[sel], keypoint_sigma=None if sg is None else sg[sel]))
        return out
