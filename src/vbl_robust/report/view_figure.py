"""The gallery's figure (:func:`worst_view`): an image and its perturbed version side by side, true and
predicted runway corners drawn, each panel a square crop around its corners."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .figure_style import new_fig

#: The gallery's corner styles (:func:`worst_view`): ground truth and the detector's prediction.
TRUE_CORNERS = {"color": "#2ca02c", "marker": "o", "linestyle": "-"}
PREDICTED_CORNERS = {"color": "#d62728", "marker": "x", "linestyle": "--"}


def _finite_in_frame(points: np.ndarray, width: int, height: int) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return np.clip(p[np.isfinite(p).all(axis=1)], [-0.5, -0.5], [width - 0.5, height - 0.5])


def crop_side(points: np.ndarray, width: int, height: int, *, factor: float = 4.0, min_px: float = 128.0) -> float:
    """The side (pixels) of a square crop around the finite rows of ``points`` ``(k, 2)`` (clipped to the frame):
    ``factor`` × their extent, at least ``min_px``, at most the frame's longer side."""
    p = _finite_in_frame(points, width, height)
    extent = float(np.max(p.max(axis=0) - p.min(axis=0))) if len(p) else math.inf
    return min(max(factor * extent, min_px), float(max(width, height)))


def crop_window(points: np.ndarray, width: int, height: int, side: float) -> tuple[float, float, float, float]:
    """``(x0, x1, y0, y1)``: a square window of ``side`` pixels centred on the finite rows of ``points`` ``(k, 2)``,
    moved inside the frame (the whole frame when no point is finite)."""
    p = _finite_in_frame(points, width, height)
    if not len(p):
        return -0.5, width - 0.5, -0.5, height - 0.5
    c = (p.min(axis=0) + p.max(axis=0)) / 2
    x0 = float(np.clip(c[0] - side / 2, -0.5, max(-0.5, width - 0.5 - side)))
    y0 = float(np.clip(c[1] - side / 2, -0.5, max(-0.5, height - 0.5 - side)))
    return x0, min(x0 + side, width - 0.5), y0, min(y0 + side, height - 0.5)


def _corners(ax: Any, pts: np.ndarray, style: Mapping[str, Any]) -> None:
    """A quadrilateral through four corners (closed), the first (TR) with a larger marker."""
    closed = np.vstack([pts, pts[:1]])
    ax.plot(closed[:, 0], closed[:, 1], color=style["color"], linestyle=style["linestyle"], linewidth=1.4)
    ax.plot(pts[:, 0], pts[:, 1], linestyle="none", color=style["color"], marker=style["marker"], markersize=5)
    ax.plot(pts[:1, 0], pts[:1, 1], linestyle="none", color=style["color"], marker=style["marker"], markersize=10,
            markerfacecolor="none" if style["marker"] == "o" else None)


def worst_view(original: np.ndarray, perturbed: np.ndarray, true_before: np.ndarray, true_after: np.ndarray,
               predicted: np.ndarray | None, *, confident: bool = True,
               titles: tuple[str, str] = ("unperturbed", "perturbed at θ*")) -> Figure:
    """A gallery entry: the unperturbed image with its true corners beside the perturbed one with the true corners
    moved by the perturbation (``true_after``) and the corners the detector predicted (``predicted``; None: only
    the true corners are drawn; ``confident`` False: they gave no pose, a flagged failure). Images ``(H, W, 3)``,
    corners ``(4, 2)`` pixels (TR, TL, BL, BR); each panel is a square crop around its corners
    (:func:`crop_window`), both at one scale (the larger of their :func:`crop_side`) unless one is over 3× the
    other (predicted corners far off)."""
    fig, axes = new_fig(1, 2, size=(6.4, 3.6))
    h, w = original.shape[:2]
    panels = ((original, true_before, None), (perturbed, true_after, predicted))
    shown = [truth if pred is None else np.vstack([truth, pred]) for _, truth, pred in panels]
    sides = [crop_side(pts, w, h) for pts in shown]
    if max(sides) <= 3 * min(sides):
        sides = [max(sides)] * 2
    for ax, (im, truth, pred), pts, side, title in zip(axes, panels, shown, sides, titles, strict=True):
        ax.imshow(im)
        x0, x1, y0, y1 = crop_window(pts, w, h, side)
        _corners(ax, np.asarray(truth, dtype=np.float64), TRUE_CORNERS)
        if pred is not None:
            _corners(ax, np.asarray(pred, dtype=np.float64), PREDICTED_CORNERS)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(f"{x1 - x0:.0f} px crop of the {w}×{h} image", fontsize=8)
    handles = [Line2D([], [], color=TRUE_CORNERS["color"], marker="o", label="true corners")]
    if predicted is not None:
        handles.append(Line2D([], [], color=PREDICTED_CORNERS["color"], marker="x", linestyle="--",
                              label="predicted corners" + ("" if confident else " (no pose: flagged)")))
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=2, frameon=False)
    return fig
