"""Runway-corner detectors: the protocol every detector implements, σ_select, and the detectors.

- :mod:`.base` — the protocol (``detect(context)``, ``detect_top(context)``, declared capabilities), the
  :class:`~.base.DetectContext` a detector asks for its views, :class:`Detections`, :func:`~.base.select`;
- :mod:`.windows` — detector-side geometry (letterbox, crop windows from corners);
- :mod:`.pose` — the pose-model base (single pass); :mod:`.ultralytics` (``.pt``) and :mod:`.onnx` models;
  :mod:`.onnx_twin` — a checked torch twin of an ONNX model, for gradient searches;
- :mod:`.twostage` — two pose models composed: whole image, then a crop; :mod:`.oracle` — ground truth;
- :mod:`.shipped` — the shipped model (path, design, validation, caveats) and :class:`~.shipped.DetectorSpec`.
"""

from .base import Detections

__all__ = ["Detections"]
