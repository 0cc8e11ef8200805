"""The gallery's figure (:func:`worst_view`): an image and its perturbed version side by side, true and
predicted runway corners drawn on both, each panel a crop scaled to the runway and drawn pixel by pixel
(nearest-neighbour) so that a one-pixel shift of a corner is visible, each corner's shift printed under it."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .figure_style import new_fig

#: The gallery's corner styles (:func:`worst_view`): ground truth and the detector's prediction.
TRUE_CORNERS = {"color": "#2ca02c", "marker": "o", "linestyle": "-"}
PREDICTED_CORNERS = {"color": "#d62728", "marker": "x", "linestyle": "--"}
#: The corners' names in their order (the runway's far threshold is the image's top).
CORNER_NAMES = ("TR", "TL", "BL", "BR")


def _finite_in_frame(points: np.ndarray, width: int, height: int) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return np.clip(p[np.isfinite(p).all(axis=1)], [-0.5, -0.5], [width - 0.5, height - 0.5])


def corner_shifts(predicted: np.ndarray | None, truth: np.ndarray) -> np.ndarray | None:
    """``(4,)`` the distance (pixels) from each predicted corner to the true one, TR TL BL BR; None without a
    prediction."""
    if predicted is None:
        return None
    return np.linalg.norm(np.asarray(predicted, dtype=np.float64) - np.asarray(truth, dtype=np.float64), axis=1)


def shifts_text(shifts: Sequence[float] | None) -> str:
    """``"TR 1.2, TL 0.4, BL 2.0, BR 0.9 px"``; ``"–"`` without shifts."""
    if shifts is None:
        return "–"
    return ", ".join(f"{n} {v:.1f}" for n, v in zip(CORNER_NAMES, shifts, strict=True)) + " px"


def crop_side(points: np.ndarray, width: int, height: int, *, factor: float = 1.6, min_px: float = 24.0) -> float:
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
               predicted: np.ndarray | None, *, predicted_before: np.ndarray | None = None, confident: bool = True,
               titles: tuple[str, str] = ("unperturbed", "perturbed at θ*")) -> Figure:
    """A gallery entry: the unperturbed image with its true corners and the corners the detector predicted there
    (``predicted_before``; None: not stored) beside the perturbed one with the true corners moved by the
    perturbation (``true_after``) and the corners predicted at θ* (``predicted``; None: only the true corners are
    drawn; ``confident`` False: they gave no pose, a flagged failure). Images ``(H, W, 3)``, corners ``(4, 2)``
    pixels (TR, TL, BL, BR).

    Each panel is a square crop around its corners, :func:`crop_side` (1.6 × their extent, at least 24 px): at
    ≈ 5 km a runway spans a few dozen pixels, so the crop is drawn nearest-neighbour, each image pixel a visible
    block, and a red segment joins each true corner to its prediction; under the panel, each corner's shift in
    pixels (:func:`corner_shifts`). Both panels share one scale unless one is over 3× the other (predicted corners
    far off)."""
    fig, axes = new_fig(1, 2, size=(7.2, 4.8))
    h, w = original.shape[:2]
    panels = ((original, true_before, predicted_before), (perturbed, true_after, predicted))
    shown = [truth if pred is None else np.vstack([truth, pred]) for _, truth, pred in panels]
    sides = [crop_side(pts, w, h) for pts in shown]
    if max(sides) <= 3 * min(sides):
        sides = [max(sides)] * 2
    for ax, (im, truth, pred), pts, side, title in zip(axes, panels, shown, sides, titles, strict=True):
        ax.imshow(im, interpolation="nearest")
        x0, x1, y0, y1 = crop_window(pts, w, h, side)
        truth = np.asarray(truth, dtype=np.float64)
        _corners(ax, truth, TRUE_CORNERS)
        if pred is not None:
            pred = np.asarray(pred, dtype=np.float64)
            for a, b in zip(truth, pred, strict=True):  # each corner's shift, true → predicted
                ax.plot([a[0], b[0]], [a[1], b[1]], color=PREDICTED_CORNERS["color"], linewidth=1.0)
            _corners(ax, pred, PREDICTED_CORNERS)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y1, y0)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(title, fontsize=10)
        shift = corner_shifts(pred, truth)
        ax.set_xlabel(("corner shift: " + shifts_text(shift).replace(", BL", ",\nBL") if shift is not None
                       else "no predicted corners") + f"\n{x1 - x0:.0f} px crop of the {w}×{h} image, 1 block = 1 px",
                      fontsize=8)
    handles = [Line2D([], [], color=TRUE_CORNERS["color"], marker="o", label="true corners")]
    if predicted is not None or predicted_before is not None:
        handles.append(Line2D([], [], color=PREDICTED_CORNERS["color"], marker="x", linestyle="--",
                              label="predicted corners" + ("" if confident else " (at θ*: no pose, flagged)")))
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=2, frameon=False)
    return fig
