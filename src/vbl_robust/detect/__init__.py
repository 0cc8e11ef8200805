"""Runway-corner detectors: the protocol every detector implements, σ_select, and the oracle detector.

The protocol (black-box ``detect`` and differentiable ``detect_top``, coordinates, ``context``) is documented
in :mod:`.base`; adapters for ultralytics ``.pt`` and ONNX models implement it.
"""

from .base import (
    DEFAULT_CONF_THRESHOLD,
    DetectContext,
    Detections,
    Detector,
    DifferentiableDetector,
    Selection,
    select,
)
from .oracle import OracleDetector

__all__ = [
    "DEFAULT_CONF_THRESHOLD",
    "DetectContext",
    "Detections",
    "Detector",
    "DifferentiableDetector",
    "OracleDetector",
    "Selection",
    "select",
    "UltralyticsDetector",
    "OnnxDetector",
    "TwoStageDetector",
    "default_detector",
]

# The model adapters import ultralytics/onnxruntime: resolved on first use only.
_LAZY = {
    "UltralyticsDetector": ".ultralytics",
    "default_detector": ".ultralytics",
    "OnnxDetector": ".onnx",
    "TwoStageDetector": ".twostage",
}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value
