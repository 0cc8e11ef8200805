"""The vulnerability zones of a 1-D or 2-D box drawn to a PNG (:func:`plot_zones`), with an optional landscape
under them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..search.zones import BREACHED, CLASSES, RULED_OUT, UNDECIDED, ZoneMap
from .figure_style import axis_label, wrapped

COLOURS = {BREACHED: "#d62728", UNDECIDED: "#bdbdbd", RULED_OUT: "#2ca02c"}


#: The colour map of a landscape drawn under the zones: blues, so that no zone colour (red, grey, green) vanishes
#: into it (viridis' greens swallowed the "ruled out" cells).
LANDSCAPE_CMAP = "Blues"


def plot_zones(zone_map: ZoneMap, path: str | Path, *, landscape: tuple[np.ndarray, np.ndarray] | None = None,
               title: str | None = None) -> Path:
    """Draw the zones of a 1-D or 2-D box (:func:`zones_figure`) to a PNG and return the path."""
    import matplotlib.pyplot as plt

    fig = zones_figure(zone_map, landscape=landscape, title=title)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def zones_figure(zone_map: ZoneMap, *, landscape: tuple[np.ndarray, np.ndarray] | None = None,
                 title: str | None = None) -> Any:
    """The zones of a 1-D or 2-D box as a figure.

    1-D: the cells as coloured bands under the values at their centres, with ε (and ``landscape = (xs (n, 1),
    fs (n,))``, e.g. a dense grid, as a line). 2-D: the cells as coloured rectangles and their centres (with a
    ``landscape = (xs (n, 2), fs (n,))``: its values as a log-scale heat map in :data:`LANDSCAPE_CMAP` under the
    rectangles, which are then drawn translucent with edges of their class's colour, and its ε contour). Axes
    named from :data:`~vbl_robust.report.figure_style.AXIS_LABELS`; a long title wrapped to the figure's width.
    ValueError for more than two parameters or a landscape of another dimension."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import to_rgba
    from matplotlib.patches import Patch

    box = zone_map.box
    if box.dim > 2:
        raise ValueError(f"plot_zones: draws 1-D and 2-D boxes, this one has {box.dim} parameters")
    lx = lf = None
    if landscape is not None:
        lx = np.asarray(landscape[0], dtype=np.float64).reshape(len(landscape[0]), -1)
        lf = np.asarray(landscape[1], dtype=np.float64).reshape(-1)
        if lx.shape[1] != box.dim or len(lf) != len(lx):
            raise ValueError(f"plot_zones: landscape must be (xs (n, {box.dim}), fs (n,)), got xs {lx.shape}, "
                             f"fs {lf.shape}")
    fig, ax = plt.subplots(figsize=(7.0, 4.4 if box.dim == 1 else 5.6), dpi=110, layout="constrained")
    label = lambda i: axis_label(box.names[i], box.units[i])  # noqa: E731
    lo = np.array([z.lower for z in zone_map.zones]).reshape(-1, box.dim)
    hi = np.array([z.upper for z in zone_map.zones]).reshape(-1, box.dim)
    colour = [COLOURS[z.cls] for z in zone_map.zones]
    # one collection, not a patch per cell: thousands of cells draw in a fraction of a second
    if box.dim == 1:
        bands = np.stack([np.c_[lo[:, 0], np.zeros(len(lo))], np.c_[lo[:, 0], np.ones(len(lo))],
                          np.c_[hi[:, 0], np.ones(len(lo))], np.c_[hi[:, 0], np.zeros(len(lo))]], axis=1)
        ax.add_collection(PolyCollection(bands, facecolors=[to_rgba(c, 0.35) for c in colour], linewidths=0,
                                         transform=ax.get_xaxis_transform()), autolim=False)
        c = np.array([z.center[0] for z in zone_map.zones])
        v = np.array([z.value for z in zone_map.zones])
        order = np.argsort(c)
        if lx is not None:
            o = np.argsort(lx[:, 0])
            ax.plot(lx[o, 0], lf[o], color="0.3", lw=1, label="landscape")
        ax.plot(c[order], v[order], "k.", ms=3, label="cell centres")
        ax.axhline(zone_map.threshold, color="k", ls="--", lw=0.8, label=f"ε = {zone_map.threshold:g}")
        ax.set_xlabel(label(0))
        ax.set_ylabel("value")
        ax.set_xlim(box.lower[0], box.upper[0])
    else:
        if lx is not None:
            _heat_map(fig, ax, lx, lf, zone_map.threshold)
        rects = np.stack([lo, np.c_[lo[:, 0], hi[:, 1]], hi, np.c_[hi[:, 0], lo[:, 1]]], axis=1)
        if lx is None:
            cells = PolyCollection(rects, facecolors=[to_rgba(c, 0.8) for c in colour], edgecolors="white",
                                   linewidths=0.3)
        else:
            cells = PolyCollection(rects, facecolors=[to_rgba(c, 0.3) for c in colour], edgecolors=colour,
                                   linewidths=0.7)
        ax.add_collection(cells)
        c = np.array([z.center for z in zone_map.zones])
        ax.plot(c[:, 0], c[:, 1], "k.", ms=2)
        ax.set_xlim(box.lower[0], box.upper[0])
        ax.set_ylim(box.lower[1], box.upper[1])
        ax.set_xlabel(label(0))
        ax.set_ylabel(label(1))
    f = zone_map.fractions
    handles = [Patch(color=COLOURS[k], alpha=0.6, label=f"{k.replace('_', ' ')} {100 * f[k]:.1f} %") for k in CLASSES]
    extra = ax.get_legend_handles_labels()[0] if box.dim == 1 else []
    # below the axes, not loc="best" (its search takes seconds with thousands of cells), so it hides no cell
    fig.legend(handles=handles + extra, fontsize=7, loc="outside lower center", ncol=len(handles + extra))
    basis = {"sound": "sound under the given L", "estimate": "estimate K̂: not sound", "none": "no constant"}
    # a figure title (not the axes'): centred on the figure and wrapped, it cannot run past the left edge
    fig.suptitle(wrapped(title or f"{zone_map.method}: zones ({basis[zone_map.basis]})", 6.6, 9), fontsize=9)
    return fig


def _heat_map(fig: Any, ax: Any, xs: np.ndarray, fs: np.ndarray, threshold: float) -> None:
    """A 2-D landscape under the zones: a log-scale heat map on its lattice (scattered points when it is none)
    and its contour at ``threshold``; non-finite and unevaluated nodes left blank, values below 1 cm at 1 cm."""
    from matplotlib.colors import LogNorm

    finite = np.isfinite(fs)
    if not finite.any():
        return
    v = np.clip(np.where(finite, fs, np.nan), 1e-2, None)
    norm = LogNorm(vmin=min(float(np.nanmin(v)), threshold / 3), vmax=max(float(np.nanmax(v)), threshold * 1.5))
    u0, u1 = np.unique(xs[:, 0]), np.unique(xs[:, 1])
    if len(u0) > 1 and len(u1) > 1 and len(u0) * len(u1) <= 2 * len(xs):  # a lattice (complete or partly evaluated)
        grid = np.full((len(u1), len(u0)), np.nan)
        grid[np.searchsorted(u1, xs[:, 1]), np.searchsorted(u0, xs[:, 0])] = v
        im = ax.pcolormesh(u0, u1, np.ma.masked_invalid(grid), shading="nearest", norm=norm, cmap=LANDSCAPE_CMAP)
        if np.nanmin(grid) < threshold < np.nanmax(grid):
            ax.contour(u0, u1, np.ma.masked_invalid(grid), levels=[threshold], colors="black", linewidths=1.2,
                       linestyles="--")
    else:
        im = ax.scatter(xs[finite, 0], xs[finite, 1], c=v[finite], norm=norm, cmap=LANDSCAPE_CMAP, s=8)
    fig.colorbar(im, ax=ax).set_label(f"landscape value (log scale; dashed: ε = {threshold:g})", fontsize=8)

