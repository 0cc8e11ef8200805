"""vbl-robust: find the physically plausible perturbations that make a vision-based landing pipeline fail.

Public API (names are resolved lazily, so ``import vbl_robust`` stays cheap)::

    import vbl_robust as vr
    samples = vr.scenes.generate(10, seed=0)
    box = vr.ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    objective = vr.Objective(samples[0], vr.OracleDetector(), box, pnp="ippe_lm")
    result = vr.search.maximize(objective, box, method="georobust", max_evals=200)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .space import ParameterBox

__version__ = "0.1.0"

# public name -> (module, attribute); attribute None = the module itself
_LAZY: dict[str, tuple[str, str | None]] = {
    "Sample": ("vbl_robust.data.sample", "Sample"),
    "Objective": ("vbl_robust.pipeline", "Objective"),
    "OracleDetector": ("vbl_robust.detect.oracle", "OracleDetector"),
    "UltralyticsDetector": ("vbl_robust.detect.ultralytics", "UltralyticsDetector"),
    "OnnxDetector": ("vbl_robust.detect.onnx", "OnnxDetector"),
    "default_detector": ("vbl_robust.detect.shipped", "default_detector"),
    "scenes": ("vbl_robust.scenes", None),
    "data": ("vbl_robust.data", None),
    "search": ("vbl_robust.search", None),
    "geometry": ("vbl_robust.geometry", None),
    "perturb": ("vbl_robust.perturb", None),
    "pnp": ("vbl_robust.pnp", None),
    "detect": ("vbl_robust.detect", None),
    "campaigns": ("vbl_robust.campaigns", None),
    "report": ("vbl_robust.report", None),
    "zones": ("vbl_robust.zones", None),
}

__all__ = ["ParameterBox", "__version__", *_LAZY]

if TYPE_CHECKING:  # pragma: no cover
    from . import data, geometry, scenes, search  # noqa: F401
    from .data.sample import Sample  # noqa: F401


def __getattr__(name: str) -> Any:
    try:
        module, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'vbl_robust' has no attribute {name!r}") from None
    mod = importlib.import_module(module)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
