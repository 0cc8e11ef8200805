"""Provenance of a run: code version, detector identity (model file SHA-256), dataset identity, sample fingerprints.

A :class:`DetectorSpec` names a detector by *how to build it* (kind + path), not by an object, so the same
spec rebuilds the detector once per process — in the local runner and in every Ray worker — and its identity
(kind, file SHA-256) goes into each job's key: results of two different models never mix in one store.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import logging
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from .spec import digest

logger = logging.getLogger(__name__)

DETECTOR_KINDS = ("oracle", "default", "ultralytics", "onnx", "factory")


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


@cache
def code_version() -> str:
    """``git describe --always --dirty`` of the source checkout when there is one, else the package version."""
    import vbl_robust

    src = Path(vbl_robust.__file__).resolve().parent
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=src, capture_output=True,
                             text=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return f"{vbl_robust.__version__}+git.{out.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    return vbl_robust.__version__


def sample_fingerprint(sample: Any) -> str:
    """Digest of a sample's identity and geometry (id, size, K, corners 3D/2D, true position)."""
    return digest({
        "id": sample.id, "size": [int(sample.width), int(sample.height)], "K": sample.K.tolist(),
        "corners_3d": sample.corners_3d.tolist(), "corners_2d": sample.corners_2d.tolist(),
        "position": sample.position.tolist(),
    }, 16)


def dataset_identity(samples: Sequence[Any], source: dict[str, Any]) -> dict[str, Any]:
    """``{"source": ..., "n": ..., "sha256": ...}``: where the samples came from and a digest of all of them."""
    fps = [sample_fingerprint(s) for s in samples]
    return {"source": source, "n": len(samples), "sha256": digest(fps)}


def default_model_path() -> Path | None:
    """The shipped model's weights file if it is installed, else None."""
    try:
        mod = importlib.import_module("vbl_robust.detect.ultralytics")
    except ImportError:
        return None
    path = getattr(mod, "DEFAULT_MODEL", None)
    if path is None or not hasattr(mod, "default_detector") or not Path(path).is_file():
        return None
    return Path(path)


def default_model_info() -> dict[str, Any]:
    """The shipped model's ``default.json`` (design, input size, version, validation), ``{}`` if unreadable."""
    path = default_model_path()
    if path is None:
        return {}
    try:
        info = json.loads((path.parent / "default.json").read_text())
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def default_model_status() -> str:
    """``""`` when the shipped model is installed and validated, else why not (one line).

    *Validated* (``"validated": true`` in ``default.json``): ``benchmarks/bench_detector.py`` showed the model
    meets the gates for auditing with it — detection ≥ 97 % and nominal survival ≥ 90 % on the held-out set;
    below them a robustness figure mostly measures the detector's nominal failures. Goals beyond the gates that
    are still open are listed in ``"open_goals"`` (:func:`default_model_caveats`) and shown with every run.
    """
    path = default_model_path()
    if path is None:
        return "the shipped detector model is not installed"
    if default_model_info().get("validated") is not True:
        return (f"the shipped detector model ({path.name}) does not meet its validation gates yet "
                f"(see {path.parent / 'MODEL_CARD.md'})")
    return ""


def default_model_caveats(info: dict[str, Any] | None = None) -> list[str]:
    """The shipped model's open accuracy goals (``"open_goals"`` of ``default.json``, or of ``info`` when given),
    one line each."""
    goals = (default_model_info() if info is None else info).get("open_goals") or []
    return [str(g) for g in goals] if isinstance(goals, list) else [str(goals)]


@dataclass(frozen=True)
class DetectorSpec:
    """How to build a detector.

    Kinds: ``"oracle"`` (projects the ground truth: a perfect detector), ``"default"`` (the shipped model),
    ``"ultralytics"`` (a user's ``.pt``; ``trust=True`` required for files outside the package), ``"onnx"``,
    ``"factory"`` (``path`` = ``"module:callable"`` returning a detector; for tests and plug-ins).
    ``options["design"]`` (model kinds): ``"single"`` or ``"twostage"`` (:func:`~vbl_robust.detect.ultralytics.
    with_design`); the shipped model defaults to its ``default.json``, a user's model to a single pass.
    """

    kind: str
    path: str | None = None
    trust: bool = False
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in DETECTOR_KINDS:
            raise ValueError(f"detector kind must be one of {DETECTOR_KINDS}, got {self.kind!r}")
        if self.kind in ("ultralytics", "onnx", "factory") and not self.path:
            raise ValueError(f"detector kind {self.kind!r} needs a path")
        if self.kind in ("ultralytics", "onnx") and not Path(self.path).is_file():
            raise FileNotFoundError(f"{self.path}: model file not found")

    @classmethod
    def auto(cls, *, oracle_noise_px: float = 0.0) -> DetectorSpec:
        """The shipped model when it is installed and validated, else the oracle detector (with a warning).

        A shipped model is *validated* when its ``default.json`` says ``"validated": true`` — set only after
        ``benchmarks/bench_detector.py`` showed it passes the gates of its model card. An undertrained
        model would turn every audit into a report on a broken detector, so it is used only when asked for
        (``DetectorSpec("default")``, ``--model default``).
        """
        why = default_model_status()
        if why == "":
            return cls("default")
        logger.warning("%s; using the oracle detector (ground-truth keypoints%s)", why,
                       f", {oracle_noise_px:g} px fixed noise" if oracle_noise_px else "")
        return cls.oracle(oracle_noise_px)

    @classmethod
    def oracle(cls, noise_px: float = 0.0) -> DetectorSpec:
        """The oracle detector, with ``noise_px`` of fixed per-image corner noise (0: exact corners)."""
        return cls("oracle", options={"noise_px": noise_px} if noise_px else {})

    @classmethod
    def from_path(cls, path: str | Path, *, trust: bool = False) -> DetectorSpec:
        p = Path(path)
        if p.suffix.lower() == ".onnx":
            return cls("onnx", str(p))
        if p.suffix.lower() == ".pt":
            return cls("ultralytics", str(p), trust=trust)
        raise ValueError(f"--model {path}: expected a .pt (ultralytics) or .onnx file")

    @property
    def model_file(self) -> Path | None:
        if self.kind == "default":
            return default_model_path()
        if self.kind in ("ultralytics", "onnx"):
            return Path(self.path)
        return None

    @property
    def name(self) -> str:
        if self.kind == "oracle":
            return "oracle (ground-truth keypoints)"
        if self.kind == "default":
            return f"shipped model ({self.model_file.name if self.model_file else 'missing'})"
        return f"{self.kind}: {self.path}"

    def identity(self) -> dict[str, Any]:
        """JSON identity: kind, name, model file SHA-256 (None for the oracle), options; for the shipped model
        also the SHA-256 of its ``default.json`` (single or two-stage, input size)."""
        f = self.model_file
        ident = {"kind": self.kind, "name": self.name, "path": None if f is None else str(f),
                 "sha256": None if f is None else file_sha256(f), "options": dict(self.options)}
        if self.kind == "factory":
            ident["factory"] = self.path
        if self.kind == "default" and f is not None and (f.parent / "default.json").is_file():
            ident["config_sha256"] = file_sha256(f.parent / "default.json")
            info = default_model_info()
            if "version" in info:
                ident["name"] += f" v{info['version']}"
            if goals := default_model_caveats(info):
                ident["open_goals"] = goals
        return ident

    def key(self) -> str:
        """Digest of what determines the detector's outputs (not where the file lives)."""
        ident = self.identity()
        return digest({k: v for k, v in ident.items() if k not in ("name", "path")}, 24)

    def build(self) -> Any:
        """Construct the detector (call once per process; models are heavy)."""
        if self.kind == "oracle":
            from ..detect.oracle import OracleDetector

            return OracleDetector(**self.options)
        if self.kind == "default":
            from ..detect.ultralytics import default_detector

            return default_detector(**self.options)
        if self.kind in ("ultralytics", "onnx"):
            from ..detect.ultralytics import UltralyticsDetector, with_design

            opts = dict(self.options)
            design = opts.pop("design", "single")
            if self.kind == "onnx":
                from ..detect.onnx import OnnxDetector

                return with_design(OnnxDetector(self.path, **opts), design)
            return with_design(UltralyticsDetector(self.path, trust=self.trust, **opts), design)
        module, _, attr = self.path.partition(":")
        return getattr(importlib.import_module(module), attr)(**self.options)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "path": self.path, "trust": self.trust, "options": dict(self.options)}
