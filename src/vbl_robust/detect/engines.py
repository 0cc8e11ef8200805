"""Inference engines for the black-box path: the same model on torch, ONNX Runtime or OpenVINO, always fp32.

An engine may change speed, never the outputs beyond 1e-3 px (tested per engine against torch). A ``.pt`` model
is exported to ONNX once (ultralytics' exporter, dynamic batch) into a cache keyed by the checkpoint's SHA-256
(``$VBL_ROBUST_CACHE`` or ``~/.cache/vbl_robust``), then run by ONNX Runtime (CPU provider) or OpenVINO (CPU, fp32
enforced, see :mod:`.openvino`). The differentiable path (APGD) always runs in torch: :class:`EnginePose` sends a
forward to the engine only when no gradient is needed.

``auto``: ONNX Runtime when installed (a required dependency), else torch. The rule is a measurement on this
project's 2-core AVX-512 CPU (issue 13, 320 px, one thread, batch 1 / 8 / 32, images/s): torch 59 / 66 / 67,
ONNX Runtime 92 / 93 / 89, OpenVINO fp32 91 / 96 / 88 — ONNX Runtime is as fast as OpenVINO in fp32 and needs no
extra package; ``benchmarks/bench_engines.py`` re-measures it side by side.
"""

from __future__ import annotations

import importlib.util
import logging
import os
from pathlib import Path

import torch

from vbl_robust.digest import file_sha256

from .pose import PoseDetector

logger = logging.getLogger(__name__)

__all__ = ["ENGINES", "EnginePose", "cache_dir", "exported_onnx", "installed_engines", "resolve_engine",
           "with_engine"]

ENGINES = ("torch", "onnxruntime", "openvino")


def installed_engines() -> tuple[str, ...]:
    """The engines whose packages are importable here (torch always)."""
    return tuple(e for e in ENGINES if e == "torch" or importlib.util.find_spec(e) is not None)


def resolve_engine(engine: str, device: str = "cpu") -> str:
    """``auto`` → the engine the documented rule picks (module docstring; on a CUDA ``device``: torch, see
    :mod:`.device`); a name → itself if installed."""
    if engine == "auto":
        if str(device).startswith("cuda"):
            return "torch"
        return "onnxruntime" if "onnxruntime" in installed_engines() else "torch"
    if engine not in ENGINES:
        raise ValueError(f"engine must be auto or one of {', '.join(ENGINES)}, got {engine!r}")
    if engine not in installed_engines():
        raise ValueError(f"engine {engine!r} is not installed (pip install {engine})")
    return engine


def cache_dir() -> Path:
    """Where exported models are kept: ``$VBL_ROBUST_CACHE`` or ``~/.cache/vbl_robust``."""
    return Path(os.environ.get("VBL_ROBUST_CACHE") or Path.home() / ".cache" / "vbl_robust")


def exported_onnx(pt_path: str | Path, *, trust: bool, imgsz: int) -> Path:
    """The ONNX export of a ``.pt`` (made once, cached by the checkpoint's SHA-256 and the input size).

    Processes that need the same export at once (a campaign's workers on a fresh machine) take turns on a file
    lock (``filelock``): one exports, the others then find the file."""
    from filelock import FileLock

    from .onnx import export_onnx

    out = cache_dir() / "onnx" / f"{file_sha256(pt_path)[:24]}_{int(imgsz)}.onnx"
    if out.is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(str(out.with_suffix(".lock"))):
        if not out.is_file():
            logger.info("exporting %s to ONNX (once) → %s", pt_path, out)
            export_onnx(pt_path, out, trust=trust, imgsz=int(imgsz))
    return out


class EnginePose(PoseDetector):
    """A torch pose model whose forwards without gradient run on another engine (same weights, fp32).

    ``engine``/``precision`` name what runs the black-box path; a forward on views that need a gradient (the
    differentiable path) runs the torch model.
    """

    differentiable = True

    def __init__(self, torch_model: PoseDetector, engine_model: PoseDetector, engine: str) -> None:
        if engine_model.imgsz != torch_model.imgsz:
            raise ValueError(f"EnginePose: input sizes differ ({engine_model.imgsz} vs {torch_model.imgsz})")
        self.torch_model, self.engine_model, self.engine = torch_model, engine_model, engine
        self.imgsz, self.nc, self.chunk = torch_model.imgsz, torch_model.nc, torch_model.chunk
        self.gives_sigma = torch_model.gives_sigma
        self.input_size = torch_model.input_size
        self.precision = str(getattr(engine_model, "precision", "fp32"))
        self.device = getattr(torch_model, "device", torch.device("cpu"))

    def __repr__(self) -> str:
        return f"EnginePose({self.torch_model!r}, engine={self.engine})"

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() and views.requires_grad:
            return self.torch_model.raw(views)
        return self.engine_model.raw(views)


def with_engine(model: PoseDetector, engine: str, *, trust: bool = False) -> PoseDetector:
    """``model`` (an :class:`~vbl_robust.detect.ultralytics.UltralyticsDetector`) with its black-box forwards on
    ``engine`` (``auto`` resolved by :func:`resolve_engine`); ``torch`` returns it unchanged."""
    device = str(getattr(model, "device", "cpu"))
    engine = resolve_engine(engine, device)
    if engine == "torch":
        return model
    onnx_path = exported_onnx(model.path, trust=trust, imgsz=model.imgsz)
    threads = torch.get_num_threads()
    if engine == "onnxruntime":
        from .onnx import OnnxDetector

        fast = OnnxDetector(onnx_path, imgsz=model.imgsz, chunk=model.chunk, threads=threads, device=device)
    else:
        from .openvino import OpenVinoDetector

        fast = OpenVinoDetector(onnx_path, imgsz=model.imgsz, chunk=model.chunk, threads=threads, device=device)
    return EnginePose(model, fast, engine)
