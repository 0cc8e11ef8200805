"""Figure of a sequence audit: per-frame error against distance along the approach, nominal and worst θ.

Conventions of :mod:`vbl_robust.report.figures`: errors in metres on a log axis, ε_safe a dotted red line; the
distance axis runs from far (left) to the threshold (right), the way the aircraft flies.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_errors_along_approach"]

_EPS_STYLE = {"color": "#d62728", "linestyle": ":", "linewidth": 1.2}
#: Errors below this are drawn at it (the oracle's exact errors are ~1e-9 m; a log axis needs a floor).
FLOOR_M = 1e-3


def plot_errors_along_approach(curves: Sequence[Mapping[str, Any]], path: str | Path | None = None, *,
                               eps_m: float = 1000.0, penalty_m: float = 5000.0, title: str | None = None):
    """Draw the per-frame errors of each sequence against its distance from the LTP.

    Args:
        curves: one mapping per sequence: ``sequence_id``, ``distances_m`` ``(F,)``, ``nominal_m`` ``(F,)`` (the
            unperturbed θ, dashed) and ``worst_m`` ``(F,)`` (the worst θ found, solid; optional), metres.
        path: save the figure there as PNG (and close it); None: return it open.
        eps_m, penalty_m: ε_safe (dotted red) and the failure penalty (thin grey), metres.

    Returns:
        The :class:`matplotlib.figure.Figure` (closed when saved), or the path when ``path`` was given.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.0, 4.5))
    colours = plt.get_cmap("tab10")
    for j, c in enumerate(curves):
        d = np.asarray(c["distances_m"], dtype=np.float64)
        colour = colours(j % 10)
        label = str(c["sequence_id"]) if len(curves) <= 10 else None
        ax.plot(d, np.maximum(np.asarray(c["nominal_m"], dtype=np.float64), FLOOR_M), "--", color=colour,
                linewidth=1.0, alpha=0.8)
        if c.get("worst_m") is not None:
            ax.plot(d, np.maximum(np.asarray(c["worst_m"], dtype=np.float64), FLOOR_M), "-", color=colour,
                    linewidth=1.6, marker=".", markersize=3, label=label)
    ax.axhline(eps_m, **_EPS_STYLE, label=f"ε_safe = {eps_m:g} m")
    ax.axhline(penalty_m, color="grey", linewidth=0.8, alpha=0.6, label=f"failure ({penalty_m:g} m)")
    ax.plot([], [], "--", color="black", linewidth=1.0, label="nominal θ")
    ax.plot([], [], "-", color="black", linewidth=1.6, label="worst θ")
    ax.set_yscale("log")
    ax.set_xlabel("distance from the runway threshold (m)")
    ax.set_ylabel("position error (m)")
    ax.invert_xaxis()
    ax.grid(True, which="major", alpha=0.3)
    ax.set_title(title or "Error along the approach: nominal (dashed) and worst θ (solid)")
    ax.legend(fontsize=7, loc="best", ncol=2)
    fig.tight_layout()
    if path is None:
        return fig
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p
