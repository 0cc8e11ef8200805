"""YOLOv8/YOLO11/YOLO26-pose runway-corner detectors from ultralytics ``.pt`` checkpoints (a YOLO26-pose model's
keypoint σ is carried: :class:`PoseWithSigma`).

:func:`load_pose_model` loads and checks a checkpoint (a pickle: only trusted files, see *trust*);
:class:`UltralyticsDetector` runs it as a :class:`~vbl_robust.detect.pose.PoseDetector` (letterboxed views,
both the black-box and the differentiable path). The shipped model and the two-stage design are in
:mod:`.shipped` and :mod:`.twostage`.

Trust: a ``.pt`` file runs code when it is loaded, so a file outside the installed ``vbl_robust`` package is
loaded only with ``trust=True`` (CLI ``--trust-model``); files inside the package (the shipped model) are part
of the installed code and trusted as such.
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch

from ..consent import packaged
from .offline import import_ultralytics
from .pose import PoseDetector

logger = logging.getLogger(__name__)

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
    if not (trust or packaged(p)):
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


def has_sigma_head(model: torch.nn.Module) -> bool:
    """Whether an (unfused) ultralytics pose model has a keypoint-uncertainty head (YOLO26-pose's ``cv4_sigma``)."""
    return getattr(model.model[-1], "cv4_sigma", None) is not None


class PoseWithSigma(torch.nn.Module):
    """A YOLO26-pose model whose raw output also carries each anchor's keypoint σ: ``(B, 4 + nc + 12 + 8, A)``,
    the 8 channels σ_x, σ_y per corner in view pixels (:func:`~vbl_robust.detect.pose.split_sigma`).

    Ultralytics computes the σ head only in training (its ``fuse`` drops it): this module keeps the head's 1×1 σ
    convolutions, reads the keypoint branch's features with forward hooks on ``cv4`` and applies them, as the
    training loss does: ``σ = sigmoid(raw) · stride`` (the loss works in grid units, ``σ`` in pixels here). The
    keypoints themselves are ultralytics' unchanged. Written by hand: ultralytics exposes no σ at inference.
    """

    def __init__(self, model: torch.nn.Module) -> None:
        super().__init__()
        head = model.model[-1]
        if not has_sigma_head(model):
            raise ValueError(f"{type(head).__name__}: the model has no keypoint-uncertainty head (cv4_sigma)")
        self.sigma_convs = head.cv4_sigma  # kept before fuse() drops it from the head
        self.model = model.fuse() if hasattr(model, "fuse") else model
        self.head = self.model.model[-1]
        self._features: list[torch.Tensor] = []
        for branch in self.head.cv4:
            branch.register_forward_hook(lambda _m, _i, out: self._features.append(out))

    @property
    def stride(self) -> torch.Tensor:
        return self.model.stride

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        self._features.clear()
        out = self.model(x)
        y = out[0] if isinstance(out, (tuple, list)) else out
        feats, n = self._features[-self.head.nl:], x.shape[0]
        raw = torch.cat([conv(f).view(n, conv.out_channels, -1) for conv, f in zip(self.sigma_convs, feats,
                                                                                   strict=True)], 2)
        self._features.clear()
        return torch.cat([y, raw.sigmoid() * self.head.strides.to(raw.dtype)], 1)


class UltralyticsDetector(PoseDetector):
    """A YOLO-pose ``.pt`` checkpoint as a runway-corner detector (single pass).

    Args:
        path: checkpoint (the shipped one: :func:`vbl_robust.detect.shipped.default_detector`).
        trust: required (True) to load a ``.pt`` from outside the package: a pickle runs code when loaded.
        imgsz: input side (multiple of 32); None → the size the model was trained at (or 640).
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (:func:`~vbl_robust.detect.device.resolve_device`).
        chunk: images per forward pass.
    """

    def __init__(self, path: str | Path, *, trust: bool = False, imgsz: int | None = None,
                 device: str = "cpu", chunk: int = 16) -> None:
        from .device import resolve_device

        device = resolve_device(device)
        self.path = Path(path)
        model, ckpt = load_pose_model(self.path, trust=trust)
        self.gives_sigma = has_sigma_head(model)
        if self.gives_sigma:
            self.model = PoseWithSigma(model).to(device)
        else:
            self.model = model.fuse().to(device) if hasattr(model, "fuse") else model.to(device)
        self.nc = len(getattr(model, "names", {0: "runway"})) or 1
        stride = int(max(getattr(self.model, "stride", torch.tensor([32.0]))))
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

    def __repr__(self) -> str:
        return f"UltralyticsDetector({str(self.path)!r}, imgsz={self.imgsz})"


__all__ = ["PoseWithSigma", "UltralyticsDetector", "has_sigma_head", "load_pose_model"]
