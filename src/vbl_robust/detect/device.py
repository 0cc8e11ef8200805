"""Which torch device runs the pipeline: ``--device auto|cpu|cuda[:N]``.

``auto`` is ``cuda`` (device 0) when ``torch.cuda.is_available()``, else ``cpu``. On a CUDA device the
perturbation, the view sampling, the detector's forward and the differentiable PnP run there
(:class:`vbl_robust.Objective` follows its detector's ``device``); the black-box PnP (``ippe_lm``) stays on the
CPU, as NumPy, on the few keypoints that come back. Engines: torch runs on any device; ONNX Runtime on CUDA only
with its CUDA provider installed (``onnxruntime-gpu``); OpenVINO on the CPU only. ``--engine auto`` picks torch on
a CUDA device (its convolutions are cuDNN's, and the views are already there), ONNX Runtime on the CPU.
"""

from __future__ import annotations

import torch

__all__ = ["resolve_device"]


def resolve_device(device: str | torch.device | None) -> str:
    """``auto``/None → ``cuda:0`` if available else ``cpu``; ``cpu``; ``cuda``/``cuda:N`` checked against the
    devices present. A one-line ``ValueError`` for anything else."""
    if isinstance(device, torch.device):
        device = str(device)
    text = "auto" if device is None else str(device).strip().lower()
    if text == "auto":
        return "cuda:0" if torch.cuda.is_available() else "cpu"
    if text == "cpu":
        return "cpu"
    if text == "cuda" or text.startswith("cuda:"):
        index = text.partition(":")[2] or "0"
        if not index.isdigit():
            raise ValueError(f"device: expected auto, cpu, cuda or cuda:N, got {device!r}")
        if not torch.cuda.is_available():
            raise ValueError(f"device {device!r}: no CUDA device is available here (torch.cuda.is_available() is "
                             "False); use --device cpu or auto")
        if int(index) >= torch.cuda.device_count():
            raise ValueError(f"device {device!r}: only {torch.cuda.device_count()} CUDA device(s) present")
        return f"cuda:{int(index)}"
    raise ValueError(f"device: expected auto, cpu, cuda or cuda:N, got {device!r}")
