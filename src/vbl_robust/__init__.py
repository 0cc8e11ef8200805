"""vbl-robust: find the physically plausible perturbations that make a vision-based landing pipeline fail.

Public API (names are resolved lazily, so ``import vbl_robust`` stays cheap)::

    import vbl_robust as vr
    samples = vr.scenes.generate(10, seed=0)
    box = vr.ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    objective = vr.Objective(samples[0], vr.OracleDetector(), box, pnp="ippe_lm")
    result = vr.search.maximize(objective, box, method="georobust", max_evals=200)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .lazy import lazy_names
from .space import ParameterBox

__version__ = "0.1.0"

# public name -> the module that defines it, or (module, None) for the module itself
_LAZY: dict[str, str | tuple[str, None]] = {
    "Sample": "vbl_robust.data.sample",
    "Objective": "vbl_robust.pipeline",
    "OracleDetector": "vbl_robust.detect.oracle",
    "UltralyticsDetector": "vbl_robust.detect.ultralytics",
    "OnnxDetector": "vbl_robust.detect.onnx",
    "default_detector": "vbl_robust.detect.shipped",
    "scenes": ("vbl_robust.scenes", None),
    "data": ("vbl_robust.data", None),
    "search": ("vbl_robust.search", None),
    "geometry": ("vbl_robust.geometry", None),
    "perturb": ("vbl_robust.perturb", None),
    "pnp": ("vbl_robust.pnp", None),
    "detect": ("vbl_robust.detect", None),
    "campaigns": ("vbl_robust.campaigns", None),
    "report": ("vbl_robust.report", None),
}

__all__ = ["ParameterBox", "__version__", *_LAZY]

if TYPE_CHECKING:  # pragma: no cover
    from . import data, geometry, scenes, search  # noqa: F401
    from .data.sample import Sample  # noqa: F401


__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals(), __all__)
