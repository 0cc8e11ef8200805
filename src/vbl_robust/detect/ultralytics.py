"""YOLOv8/YOLO11-pose runway-corner detectors from ultralytics ``.pt`` checkpoints.

Input: images as (B, 3, H, W) float RGB in [0, 1] (or uint8 (H, W, 3) / (B, H, W, 3) arrays). Each image is
letterboxed to a square ``imgsz`` view with :func:`~vbl_robust.detect.views.resample` (differentiable; grey 114
padding). Output keypoints/boxes are in **original image pixels, OpenCV convention** (pixel centres at integer
coordinates); keypoint order TR, TL, BL, BR.

Two paths over the same raw predictions ``y`` (B, 4 + nc + K·3, A) of the network (before NMS):

- :meth:`PoseDetector.detect` — black box: batched (chunks of ``chunk`` images), ``no_grad``, NMS; returns
  :class:`~vbl_robust.detect.base.Detections` per image (highest confidence first).
- :meth:`PoseDetector.detect_top` (and :meth:`PoseDetector.top`, which also gives the box) — differentiable:
  the anchor of maximum confidence (``argmax`` + ``gather``); gradients flow to the input images. NMS always
  keeps the global maximum, so it equals ``select(detect(...))``'s candidate.

Both implement the protocol of :mod:`vbl_robust.detect.base` (``input_size`` = ``imgsz``: the pipeline may
hand over images already resampled to that size).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import torch

from .base import DetectContext, Detections
from .offline import import_ultralytics
from .views import letterbox_window, resample, to_tensor, view_to_image

logger = logging.getLogger(__name__)

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
DEFAULT_MODEL = MODELS_DIR / "runway_yolov8n_pose.pt"


@dataclass
class Top:
    """Max-confidence candidate per image (differentiable): conf (B,), keypoints (B, 4, 2), boxes (B, 4)."""

    conf: torch.Tensor
    keypoints: torch.Tensor
    boxes: torch.Tensor


def split_raw(y: torch.Tensor, nc: int, nk: int = 4, kdim: int = 3) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Raw predictions (B, 4 + nc + nk·kdim, A) → (boxes xyxy (B, A, 4), conf (B, A), keypoints (B, A, nk, 2)).

    Coordinates stay in view-pixel edge coordinates (ultralytics' convention).
    """
    y = y.transpose(1, 2)
    xy, wh = y[..., :2], y[..., 2:4]
    boxes = torch.cat([xy - wh / 2, xy + wh / 2], -1)
    conf = y[..., 4:4 + nc].amax(-1) if nc > 1 else y[..., 4]
    k = y[..., 4 + nc:].reshape(*y.shape[:2], nk, kdim)[..., :2]
    return boxes, conf, k


class PoseDetector:
    """Shared logic of the ``.pt`` and ONNX detectors; subclasses implement :meth:`raw`.

    Attributes: ``imgsz`` (view side), ``nc`` (classes), ``chunk`` (images per forward pass).
    """

    imgsz: int
    nc: int = 1
    input_size: int | None
    chunk: int = 16
    differentiable: bool = True

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        """Network on views (B, 3, imgsz, imgsz) in [0, 1] → raw predictions (B, 4 + nc + 12, A)."""
        raise NotImplementedError

    def raw_chunked(self, views: torch.Tensor) -> torch.Tensor:
        """:meth:`raw` in chunks of ``chunk`` images (bounds memory)."""
        if views.shape[0] <= self.chunk:
            return self.raw(views)
        return torch.cat([self.raw(v) for v in views.split(self.chunk)], 0)

    def windows(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 3) letterbox windows of the batch (see :mod:`~vbl_robust.detect.views`)."""
        h, w = images.shape[-2:]
        return torch.tensor(letterbox_window(h, w), dtype=images.dtype).expand(images.shape[0], 3)

    def candidates(self, images) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """All anchors: boxes (B, A, 4), conf (B, A), keypoints (B, A, 4, 2), in image pixels (OpenCV)."""
        x = to_tensor(images)
        win = self.windows(x)
        return self.candidates_in_views(resample(x, win, self.imgsz), win)

    def candidates_in_views(self, views: torch.Tensor, win: torch.Tensor):
        """Like :meth:`candidates` for views already sampled (windows ``win`` (B, 3)), in image pixels."""
        boxes, conf, k = split_raw(self.raw_chunked(views), self.nc)
        b, a = conf.shape
        kp = view_to_image(k.reshape(b, a * 4, 2), win, self.imgsz).reshape(b, a, 4, 2)
        bx = view_to_image(boxes.reshape(b, a * 2, 2), win, self.imgsz).reshape(b, a, 4)
        return bx, conf, kp

    def top(self, images) -> Top:
        """Differentiable max-confidence candidate per image (gradients flow to float input images)."""
        return self.top_of(*self.candidates(images))

    @staticmethod
    def top_of(boxes: torch.Tensor, conf: torch.Tensor, kp: torch.Tensor) -> Top:
        """The max-confidence anchor of candidates (``gather``, differentiable)."""
        i = conf.argmax(dim=1)
        c = conf.gather(1, i[:, None])[:, 0]
        k = kp.gather(1, i[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
        bx = boxes.gather(1, i[:, None, None].expand(-1, 1, 4))[:, 0]
        return Top(c, k, bx)

    def detect_top(self, images, *, context: DetectContext | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Protocol form of :meth:`top`: ``(conf (B,), keypoints (B, 4, 2))``, differentiable."""
        t = self.top(images)
        return t.conf, t.keypoints

    @torch.no_grad()
    def detect(self, images, *, context: DetectContext | None = None, conf_min: float = 0.01, iou: float = 0.7,
               max_det: int = 10) -> list[Detections]:
        """Black-box path: candidates after NMS per image, highest confidence first (``context`` is ignored)."""
        import torchvision

        boxes, conf, kp = self.candidates(images)
        out = []
        for b in range(conf.shape[0]):
            keep = torch.nonzero(conf[b] >= conf_min)[:, 0]
            if keep.numel() == 0:  # the global maximum is always a candidate (selection applies the threshold)
                keep = conf[b].argmax()[None]
            sel = keep[torchvision.ops.nms(boxes[b, keep], conf[b, keep], iou)][:max_det]
            out.append(Detections(boxes[b, sel], conf[b, sel], kp[b, sel]))
        return out


def _is_packaged(path: Path) -> bool:
    try:
        path.resolve().relative_to(MODELS_DIR)
        return True
    except ValueError:
        return False


def load_pose_model(path: str | Path, *, trust: bool = False) -> tuple[torch.nn.Module, dict]:
    """Load an ultralytics pose checkpoint and check it: returns ``(model in eval mode, checkpoint dict)``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: untrusted pickle outside the package (``trust=False``), corrupt file, not a pose model,
            not 4 keypoints, or an end-to-end (YOLO26-style, NMS-free) head.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: model file not found")
    if p.suffix.lower() == ".onnx":
        raise ValueError(f"{p}: an ONNX file; use OnnxDetector (vr.OnnxDetector) for it")
    if not (trust or _is_packaged(p)):
        raise ValueError(
            f"{p}: a .pt checkpoint is a pickle and loading it runs code; pass trust=True (CLI: --trust-model) "
            "if you trust this file"
        )
    import_ultralytics()
    try:
        ckpt = torch.load(p, map_location="cpu", weights_only=False)
    except Exception as e:  # noqa: BLE001 - any unpickling failure means the same thing to the user
        raise ValueError(f"{p}: not a loadable PyTorch checkpoint ({type(e).__name__}: {e})") from e
    model = ckpt
    if isinstance(ckpt, dict):
        model = ckpt.get("ema") if ckpt.get("ema") is not None else ckpt.get("model")
    if not isinstance(model, torch.nn.Module) or not hasattr(model, "model"):
        raise ValueError(f"{p}: not an ultralytics model checkpoint (no 'model' entry)")
    head = model.model[-1]
    kpt_shape = getattr(head, "kpt_shape", None)
    if kpt_shape is None:
        raise ValueError(f"{p}: not a pose model (head {type(head).__name__}); a YOLO-pose model is required")
    if int(kpt_shape[0]) != 4:
        raise ValueError(f"{p}: pose model has {kpt_shape[0]} keypoints; runway corners need 4 (TR, TL, BL, BR)")
    if getattr(head, "end2end", False):
        raise ValueError(f"{p}: end-to-end (NMS-free, YOLO26-style) pose heads are not supported; "
                         "use a YOLOv8/YOLO11-pose model")
    model = model.float().eval()
    for q in model.parameters():
        q.requires_grad_(False)
    return model, ckpt if isinstance(ckpt, dict) else {}


class UltralyticsDetector(PoseDetector):
    """A YOLO-pose ``.pt`` checkpoint as a runway-corner detector (single pass).

    Args:
        path: checkpoint; None → the model shipped in ``vbl_robust/models`` (trusted as part of the package).
        trust: required (True) to load a ``.pt`` from outside the package: a pickle runs code when loaded.
        imgsz: input side (multiple of 32); None → the size the model was trained at (or 640).
        device: torch device (CPU in this project).
        chunk: images per forward pass.
    """

    def __init__(self, path: str | Path | None = None, *, trust: bool = False, imgsz: int | None = None,
                 device: str = "cpu", chunk: int = 16) -> None:
        self.path = Path(path) if path is not None else DEFAULT_MODEL
        model, ckpt = load_pose_model(self.path, trust=trust)
        self.model = model.fuse().to(device) if hasattr(model, "fuse") else model.to(device)
        self.nc = len(getattr(model, "names", {0: "runway"})) or 1
        stride = int(max(getattr(model, "stride", torch.tensor([32.0]))))
        train_imgsz = (ckpt.get("train_args") or {}).get("imgsz", 640)
        self.imgsz = int(imgsz or (train_imgsz if isinstance(train_imgsz, int) else max(train_imgsz)))
        if self.imgsz % stride:
            raise ValueError(f"UltralyticsDetector: imgsz must be a multiple of {stride}, got {self.imgsz}")
        self.input_size = self.imgsz
        self.device = torch.device(device)
        self.chunk = int(chunk)

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        # channels-last input: oneDNN's convolutions run 25–35 % faster on this CPU (batch 8–32, 1 thread),
        # outputs equal within 2e-4 view px
        out = self.model(views.to(self.device).contiguous(memory_format=torch.channels_last))
        return (out[0] if isinstance(out, (tuple, list)) else out).to(views.device)


def default_detector(*, imgsz: int | None = None, chunk: int = 16, design: str | None = None) -> PoseDetector:
    """The detector shipped with the package (see ``vbl_robust/models/MODEL_CARD.md``).

    ``design``: ``"twostage"`` or ``"single"`` (one pass at ``imgsz``: the paper's pipeline); None → the shipped
    default (``default.json``).
    """
    meta = MODELS_DIR / "default.json"
    kind = "single"
    if meta.exists():
        import json

        info = json.loads(meta.read_text())
        kind = info.get("detector", "single")
        imgsz = imgsz or info.get("imgsz")
    if not DEFAULT_MODEL.exists():
        raise FileNotFoundError(f"{DEFAULT_MODEL}: the shipped model is missing (reinstall vbl-robust)")
    return with_design(UltralyticsDetector(None, imgsz=imgsz, chunk=chunk), design or kind)


DESIGNS = ("single", "twostage")


def with_design(detector: PoseDetector, design: str) -> PoseDetector:
    """``detector`` as a single pass, or wrapped as the first and second pass of a two-stage detector."""
    if design not in DESIGNS:
        raise ValueError(f"detector design must be one of {DESIGNS}, got {design!r}")
    if design == "twostage":
        from .twostage import TwoStageDetector

        return TwoStageDetector(detector)
    return detector


__all__ = ["DESIGNS", "PoseDetector", "Top", "UltralyticsDetector", "default_detector", "load_pose_model",
           "split_raw", "with_design"]
