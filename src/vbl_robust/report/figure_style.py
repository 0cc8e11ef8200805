"""The conventions every report figure shares (:mod:`.figures`): one colour and marker per method
(:data:`STYLE`), the plotting order of methods, axis labels, the ε line, plain numbers on log axes, a new figure
and exact-interval error bars."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from ..analysis.levels import ANY_METHOD
from ..analysis.reference import REFERENCE_METHOD as REFERENCE
from ..analysis.summary import Summary

STYLE: dict[str, dict[str, Any]] = {
    "georobust": {"color": "#1f77b4", "marker": "o"},
    "georobust-a": {"color": "#17becf", "marker": "P"},
    "georobust-av": {"color": "#ff7f0e", "marker": "X"},
    "random": {"color": "#2ca02c", "marker": "s"},
    "apgd": {"color": "#d62728", "marker": "^"},
    "sobol": {"color": "#9467bd", "marker": "D"},
    "direct": {"color": "#8c564b", "marker": "v"},
    "direct-l": {"color": "#e377c2", "marker": "<"},
    "grid": {"color": "black", "marker": "."},
    REFERENCE: {"color": "black", "marker": "", "label": "grid (true worst case)", "linestyle": "--"},
    ANY_METHOD: {"color": "#7f7f7f", "marker": "", "label": "any method (grid included)", "linestyle": ":"},
}
#: The display name of each perturbation parameter (:data:`vbl_robust.perturb.registry.PERTURBATIONS`), with its unit: the one
#: table every figure's axes and every table of the report take their names from (:func:`axis_label`,
#: :func:`param_name`). A parameter missing here shows as its name with its unit.
AXIS_LABELS = {
    "roll_deg": "roll φ (°)", "pitch_deg": "pitch (°)", "yaw_deg": "yaw ψ (°)", "blur_px": "Gaussian blur σ (px)",
    "motion_blur_px": "motion blur length (px)", "haze": "haze h (share of airlight)", "contrast": "contrast factor α",
    "brightness": "brightness offset (full scale)", "gamma": "gamma γ", "noise_std": "noise σ (full scale)",
}
_UNIT_SYMBOLS = {"deg": "°"}
EPS_STYLE = {"color": "#d62728", "linestyle": ":", "linewidth": 1.2}


def style(method: str) -> dict[str, Any]:
    """Plot style of a method (a grey default for unknown names); its label is the optimizer class's."""
    from ..search.api import METHODS

    s = STYLE.get(method, {"color": "grey", "marker": "x"})
    label = s.get("label") or (METHODS[method].label if method in METHODS else method)
    return {"linestyle": "-", **s, "label": label}


def axis_label(name: str, unit: str = "") -> str:
    """A parameter's display name with its unit, ``"roll φ (°)"`` (:data:`AXIS_LABELS`); an unknown one as
    ``"name (unit)"``."""
    if name in AXIS_LABELS:
        return AXIS_LABELS[name]
    unit = _UNIT_SYMBOLS.get(unit, unit)
    return f"{name} ({unit})" if unit else name


def param_name(name: str) -> str:
    """A parameter's display name without its unit, ``"roll φ"``."""
    label = axis_label(name)
    return label.rsplit(" (", 1)[0] if label.endswith(")") else label


def wrapped(text: str, width_in: float, fontsize: float) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` points (a title that would
    otherwise run past the figure's edges, where the PNG clips it)."""
    import textwrap

    chars = max(20, int(width_in * 72 / (0.62 * fontsize)))  # DejaVu Sans: about 0.6 em a character
    return "\n".join(textwrap.wrap(text, chars, break_on_hyphens=False)) if len(text) > chars else text


def method_order(methods: Iterable[str]) -> list[str]:
    """The distinct ``methods`` in plotting order (the order of :data:`STYLE`, the reference and the combined
    series last)."""
    ms = list(dict.fromkeys(methods))
    return sorted(ms, key=lambda m: (m in (REFERENCE, ANY_METHOD), list(STYLE).index(m) if m in STYLE else 99, m))


PLAIN = FuncFormatter(lambda v, _: f"{v:g}")


def plain_log_axis(axis: Any) -> None:
    """Plain numbers (1000, 1500) instead of 1.5×10³ on a log axis."""
    axis.set_major_formatter(PLAIN)
    axis.set_minor_formatter(PLAIN)


def new_fig(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (6.4, 4.0), **kw: Any) -> tuple[Figure, Any]:
    """A new figure of ``nrows`` × ``ncols`` axes, ``size`` inches, in the constrained layout."""
    fig, ax = plt.subplots(nrows, ncols, figsize=size, layout="constrained", **kw)
    return fig, ax


def ci_bars(rows: Sequence[Summary]) -> np.ndarray:
    """``(2, N)`` distances from each row's survival % down and up to its exact 95 % interval (error bars)."""
    cis = [r.survival_rate.ci for r in rows]
    return np.array([[max(r.survival - c.low, 0.0) for r, c in zip(rows, cis, strict=True)],
                     [max(c.high - r.survival, 0.0) for r, c in zip(rows, cis, strict=True)]]).reshape(2, len(rows))
