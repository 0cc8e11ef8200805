"""A detector with a known failure set, for the zones tests (importable by name: DetectorSpec kind "factory")."""

from __future__ import annotations

import numpy as np

from vbl_robust.detect.base import Detections
from vbl_robust.detect.oracle import OracleDetector


class RollGate(OracleDetector):
    """The oracle, but no detection where ``roll_deg > above`` (the first parameter): every such θ is penalised
    (5000 m > ε_safe), so the breach set is exactly ``roll > above``."""

    def __init__(self, above: float = 4.0, **kw):
        super().__init__(**kw)
        self.above = float(above)

    def detect(self, context):
        dets = super().detect(context)
        roll = np.asarray(context.theta, dtype=np.float64)[:, 0]
        return [Detections.empty() if r > self.above else d for d, r in zip(dets, roll, strict=True)]
