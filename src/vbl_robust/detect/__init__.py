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
]
