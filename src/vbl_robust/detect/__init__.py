"""Runway-corner detectors: the protocol every detector implements, σ_select, and the detectors.

- :mod:`.base` — the protocol (``detect(context)``, ``detect_top(context)``, declared capabilities), the
  :class:`DetectContext` a detector asks for its views, :class:`Detections`, :func:`select`;
- :mod:`.windows` — detector-side geometry (letterbox, crop windows from corners);
- :mod:`.pose` — the pose-model base (single pass); :mod:`.ultralytics` (``.pt``) and :mod:`.onnx` models;
  :mod:`.onnx_twin` — a checked torch twin of an ONNX model, for gradient searches;
- :mod:`.twostage` — two pose models composed: whole image, then a crop; :mod:`.oracle` — ground truth;
- :mod:`.shipped` — the shipped model (path, design, validation, caveats) and :class:`DetectorSpec`.
"""

from vbl_robust.lazy import lazy_names

from .base import (
    DetectContext,
    Detections,
    Detector,
    DifferentiableDetector,
    Selection,
    Views,
    select,
)
from .oracle import OracleDetector

# The model adapters import ultralytics/onnxruntime: resolved on first use only.
_LAZY = {
    "UltralyticsDetector": ".ultralytics",
    "default_detector": ".shipped",
    "DetectorSpec": ".shipped",
    "OnnxDetector": ".onnx",
    "TwoStageDetector": ".twostage",
}

# each public name listed once: the eager re-exports above, then the lazy ones
__all__ = ["DetectContext", "Detections", "Detector", "DifferentiableDetector", "OracleDetector", "Selection",
           "Views", "select", *_LAZY]


__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals(), __all__)
