"""The report's figures (matplotlib, Agg): one function per paper figure, each taking metric tables.

Every function returns a :class:`matplotlib.figure.Figure` (the caller saves and closes it). Conventions shared
by all (:mod:`.figure_style`): survival rate in %, errors in metres, ε_safe drawn as a dashed red line, one colour
and marker per method (:data:`.figure_style.STYLE`), the dense-grid reference (true worst case up to the grid
spacing) in black dashes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ..analysis.levels import ANY_METHOD, DistanceLine
from ..analysis.metrics import ConvergenceLine, PnpLine
from ..analysis.summary import Summary
from ..specs.campaign import levels_text
from .figure_style import (
    EPS_STYLE,
    PLAIN,
    REFERENCE,
    axis_label,
    ci_bars,
    method_order,
    new_fig,
    plain_log_axis,
    style,
    wrapped,
)

__all__ = ["best_vs_evals", "convergence", "distance_profile", "family_ranking", "family_survival", "landscape_1d",
           "landscape_2d", "pnp_comparison", "risk_per_image", "runtime", "survival_before_after", "survival_per_box",
           "survival_vs_level"]


def survival_vs_level(summary: Sequence[Summary], *, title: str, xlabel: str,
                      tick_labels: Mapping[float, str] | None = None) -> Figure:
    """Survival rate (%) against the perturbation budget (box level), one line per method (+ grid reference),
    each point with its exact 95 % interval as an error bar.

    Budgets are placed at equal spacing (categories, as in the paper) and methods are offset slightly
    sideways so that coinciding curves and their bars stay visible.
    """
    fig, ax = new_fig()
    levels = sorted({r.box_level for r in summary})
    pos = {v: i for i, v in enumerate(levels)}
    methods = method_order(r.method for r in summary)
    for j, m in enumerate(methods):
        rs = sorted((r for r in summary if r.method == m), key=lambda r: r.box_level)
        st = style(m)
        dx = 0.0 if m == REFERENCE else 0.07 * (j - (len(methods) - 2) / 2)
        ax.errorbar([pos[r.box_level] + dx for r in rs], [r.survival for r in rs], yerr=ci_bars(rs),
                    marker=st["marker"], color=st["color"], linestyle=st["linestyle"], label=st["label"], markersize=6,
                    linewidth=1.6, elinewidth=0.8, capsize=2, alpha=0.9, zorder=4 if m == REFERENCE else 3)
    ax.set_xticks(range(len(levels)))
    if tick_labels:
        ax.set_xticklabels([tick_labels.get(v, f"{v:g}") for v in levels], rotation=20, ha="right", fontsize=8)
    else:
        ax.set_xticklabels([f"±{v:g}°" for v in levels])
    ax.set_ylim(-3, 103)
    ax.axhline(10, **{**EPS_STYLE, "color": "grey"}, label="10 % (φ_crit level)")
    n = max((r.n for r in summary), default=0)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("survival rate S_rate (%), 95 % CI")
    ax.set_title(f"{title}  [N = {n} images]")
    ax.grid(alpha=0.3)
    handles, names = ax.get_legend_handles_labels()  # the methods first (error bars are listed after lines)
    order = sorted(range(len(names)), key=lambda i: names[i].startswith("10 %"))
    ax.legend([handles[i] for i in order], [names[i] for i in order], fontsize=8, loc="best")
    return fig


def survival_before_after(lines: Sequence[Any], *, title: str) -> Figure:
    """Survival (%) per box of two runs paired per image (:class:`vbl_robust.report.compare.PairedLine`): per
    method the run before (dashed, open markers) and after (solid), boxes at equal spacing in level order; the
    union of the methods (``method`` "any of them") in black."""
    fig, ax = new_fig()
    boxes = [b for b, _ in sorted({ln.box: ln.level for ln in lines}.items(), key=lambda kv: (kv[1], kv[0]))]
    pos = {b: i for i, b in enumerate(boxes)}
    union = "any of them"
    for m in [*method_order(ln.method for ln in lines if ln.method != union), union]:
        rs = sorted((ln for ln in lines if ln.method == m), key=lambda ln: pos[ln.box])
        if not rs:
            continue
        st = style(m) if m != union else {"color": "black", "marker": "D", "label": union}
        x = [pos[ln.box] for ln in rs]
        ax.plot(x, [ln.before_pct for ln in rs], linestyle="--", marker=st["marker"], color=st["color"],
                markerfacecolor="none", linewidth=1.2, alpha=0.8)
        ax.plot(x, [ln.after_pct for ln in rs], linestyle="-", marker=st["marker"], color=st["color"],
                label=st["label"], linewidth=1.8)
    ax.plot([], [], "--", color="grey", label="before")
    ax.plot([], [], "-", color="grey", label="after")
    ax.set_xticks(range(len(boxes)))
    ax.set_xticklabels(boxes, rotation=20, ha="right", fontsize=8)
    ax.set_ylim(-3, 103)
    ax.set_ylabel("survival rate S_rate (%)")
    ax.set_xlabel("perturbation box")
    ax.set_title(f"{title}  [N = {max((ln.n for ln in lines), default=0)} images]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return fig


def runtime(summary: Sequence[Summary], *, axis: str, title: str, eps_safe_m: float,
            reference: Mapping[str, float] | None = None) -> Figure:
    """Two panels against the per-image budget (``axis`` "max_seconds" or "max_evals"): survival rate (with exact
    95 % intervals) and median worst error, one line per method; ``reference`` = {"survival", "median_worst_m"} of
    the dense grid."""
    fig, (a1, a2) = new_fig(1, 2, size=(10.5, 4.4))
    rows = [r for r in summary if math.isfinite(r.budget(axis))]
    for m in method_order(r.method for r in rows):
        rs = sorted((r for r in rows if r.method == m), key=lambda r: r.budget(axis))
        st = style(m)
        x = [r.budget(axis) for r in rs]
        kw = {"marker": st["marker"], "color": st["color"], "label": st["label"], "linewidth": 1.8}
        a1.errorbar(x, [r.survival for r in rs], yerr=ci_bars(rs), elinewidth=0.8, capsize=2, **kw)
        a2.plot(x, [r.median_worst_m for r in rs], **kw)
    if reference:
        st = style(REFERENCE)
        a1.axhline(reference["survival"], color="black", linestyle="--", label=st["label"])
        a2.axhline(reference["median_worst_m"], color="black", linestyle="--", label=st["label"])
    a2.axhline(eps_safe_m, **EPS_STYLE, label=f"ε_safe = {eps_safe_m:g} m")
    xl = "time budget per image (s)" if axis == "max_seconds" else "evaluation budget per image"
    for a in (a1, a2):
        a.set_xscale("log")
        xs = sorted({r.budget(axis) for r in rows})
        a.set_xticks(xs)
        a.set_xticklabels([f"{v:g}" for v in xs])
        a.minorticks_off()
        a.set_xlabel(xl)
        a.grid(alpha=0.3)
    a1.set_ylim(-3, 103)
    a1.set_ylabel("survival rate S_rate (%), 95 % CI")
    a2.set_yscale("log")
    lo, hi = a2.get_ylim()
    if hi / lo < 20:  # short range: label the minor ticks too, in plain numbers
        plain_log_axis(a2.yaxis)
    a2.set_ylabel("median worst error over images (m)")
    fig.legend(*a2.get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncol=5)
    fig.suptitle(title)
    return fig


def pnp_comparison(summary: Sequence[PnpLine]) -> Figure:
    """Median and mean (MAE) relative position error per PnP solver (over its successful solves), for the
    ground-truth and the detector keypoints; tick labels give each solver's failure count."""
    sources = list(dict.fromkeys(r.source for r in summary))
    fig, axes = new_fig(1, len(sources), size=(3.8 * len(sources), 4.2), squeeze=False)
    for k, (ax, src) in enumerate(zip(axes[0], sources, strict=True)):
        rs = [r for r in summary if r.source == src]
        x = np.arange(len(rs))
        ax.bar(x - 0.2, [r.median_rel_pct for r in rs], 0.4, label="median", color="#1f77b4")
        ax.bar(x + 0.2, [r.mae_rel_pct for r in rs], 0.4, label="mean (MAE)", color="#ff7f0e")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{r.solver}\n{r.failures}/{r.n} failed" for r in rs], fontsize=8)
        vals = np.asarray([v for r in rs for v in (r.median_rel_pct, r.mae_rel_pct)], dtype=float)
        if np.any(np.isfinite(vals) & (vals > 0)):  # a log axis needs a positive value (every solve may fail)
            ax.set_yscale("log")
        else:
            ax.text(0.5, 0.5, "no successful solve", ha="center", va="center", transform=ax.transAxes)
        if k == 0:  # each panel its own log scale, one label
            ax.set_ylabel("position error (% of slant distance)")
        ax.set_title(f"{src} keypoints")
        ax.grid(alpha=0.3, axis="y")
    fig.legend(*axes[0][0].get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncol=2)
    fig.suptitle("PnP solvers: relative camera-position error over successful solves (absolute errors: table)")
    return fig


def distance_profile(profile: Sequence[DistanceLine], *, limit_deg: float, budgets: Sequence[float],
                     title: str = "Vulnerability profile by approach distance") -> Figure:
    """Left: φ_crit (roll budget dropping survival below 10 %) per slant-distance quartile, one bar per method;
    hatched bars in the red band ≥ ``limit_deg`` = no φ_crit within the limit. Right: survival rate against the
    roll budget per quartile for the first method (solid) and the dense-grid reference (dashed) if present."""
    fig, (ax, a2) = new_fig(1, 2, size=(11.5, 4.8), gridspec_kw={"width_ratios": [1.25, 1]})
    quartiles = sorted({r.quartile for r in profile})
    methods = method_order(p.method for p in profile)
    width = 0.8 / max(len(methods), 1)
    top = limit_deg * 1.12
    ax.axhspan(limit_deg, top, color="#d62728", alpha=0.15)
    handles = [Patch(facecolor="#d62728", alpha=0.15, label=f"≥ {limit_deg:g}° (hatched): no φ_crit within the limit")]
    for i, m in enumerate(methods):
        st = style(m)
        rs = {r.quartile: r for r in profile if r.method == m}
        xs = [q + (i - (len(methods) - 1) / 2) * width for q in quartiles]
        vals = [rs[q].phi_crit if q in rs else math.nan for q in quartiles]
        for x, v in zip(xs, vals, strict=True):
            beyond = not math.isfinite(v)
            ax.bar(x, limit_deg * 1.06 if beyond else v, width * 0.9, color=st["color"], alpha=0.85,
                   hatch="//" if beyond else None, edgecolor="white")
            if not beyond:
                ax.annotate(f"{v:g}°", (x, v), ha="center", va="bottom", fontsize=7)
        handles.append(Patch(facecolor=st["color"], label=st["label"]))
    first = [r for r in profile if r.method == methods[0]] if methods else []
    lab = {r.quartile: f"Q{r.quartile}\n{r.d_min_m / 1000:.1f}–{r.d_max_m / 1000:.1f} km\n(n={r.n})" for r in first}
    ax.set_xticks(quartiles)
    ax.set_xticklabels([lab.get(q, f"Q{q}") for q in quartiles], fontsize=8)
    ax.set_ylim(0, top)
    ax.set_yticks([b for b in budgets if b <= limit_deg])
    ax.set_ylabel("φ_crit: roll budget for S_rate < 10 % (°)")
    ax.set_xlabel("slant-distance quartile (closest first)")
    ax.set_title("critical roll per quartile", fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=len(handles))
    colors = colormaps["viridis"](np.linspace(0.0, 0.85, max(len(quartiles), 1)))
    shown = [m for m in methods if m != REFERENCE][:1] + [m for m in methods if m == REFERENCE]
    for q, c in zip(quartiles, colors, strict=True):
        for m in shown:
            r = next((r for r in profile if r.method == m and r.quartile == q), None)
            if r is not None:
                a2.plot(budgets, r.survival, color=c, linestyle="--" if m == REFERENCE else "-", marker="o",
                        markersize=3, label=f"Q{q}" if m == shown[0] else None)
    a2.axhline(10, color="grey", linestyle=":", linewidth=1)
    a2.set_ylim(-3, 103)
    a2.set_xticks(list(budgets))
    a2.set_xlabel("roll budget ±b (°)")
    a2.set_ylabel("survival rate S_rate (%)")
    names = " (solid), ".join(style(m)["label"] for m in shown) + (" (dashed)" if REFERENCE in shown else " (solid)")
    a2.set_title(f"survival per quartile: {names}", fontsize=9)
    a2.grid(alpha=0.3)
    a2.legend(fontsize=7, loc="lower left")
    fig.suptitle(title)
    return fig


def convergence(conv: Sequence[ConvergenceLine], *, title: str = "GeoRobust convergence (roll ±15°)") -> Figure:
    """Top: |PO_k| per iteration; bottom: RA(k) in %. Median (line), interquartile range and 10–90th percentile
    (bands), mean (dotted) over images — percentiles, because a few images with a flat region (every box ties)
    have PO sets orders of magnitude larger than the rest."""
    fig, (a1, a2) = new_fig(2, 1, size=(6.4, 6.2), sharex=True)
    k = np.array([r.iteration for r in conv])
    for ax, name, ylabel in ((a1, "po", "|PO_k| (potentially optimal boxes)"), (a2, "ra", "RA(k): remaining area (%)")):
        def col(key: str, name: str = name) -> np.ndarray:
            return np.array([getattr(r, f"{name}_{key}") for r in conv], dtype=np.float64)

        ax.fill_between(k, col("q10"), col("q90"), color="#1f77b4", alpha=0.12, label="10–90th percentile")
        ax.fill_between(k, col("q25"), col("q75"), color="#1f77b4", alpha=0.3, label="25–75th percentile")
        ax.plot(k, col("median"), color="#1f77b4", marker="o", markersize=3, label="median")
        ax.plot(k, col("mean"), color="#d62728", linestyle=":", linewidth=1.2, label="mean")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    hi = np.nanmax([r.po_max for r in conv]) if conv else 1.0
    if hi > 60:
        a1.set_yscale("log")
        a1.yaxis.set_major_formatter(PLAIN)
    a2.axhline(20, color="grey", linestyle="--", linewidth=1, label="20 % (paper: reached by k = 10)")
    a2.axvline(10, color="grey", linestyle=":", linewidth=1)
    a2.set_ylim(0, 105)
    a2.set_xlabel("iteration k (k = 1: the whole box)")
    a1.legend(fontsize=8)
    a2.legend(fontsize=8)
    n = max((r.n for r in conv), default=0)
    fig.suptitle(f"{title}, N = {n} images")
    return fig


def landscape_2d(xs: np.ndarray, fs: np.ndarray, names: Sequence[str], overlays: Mapping[str, np.ndarray], *,
                 eps_safe_m: float, title: str, worst: Mapping[str, np.ndarray] | None = None,
                 bounds: Sequence[tuple[float, float]] | None = None) -> Figure:
    """Heat map of L over a 2-D grid (``xs`` (n, 2), ``fs`` (n,); a grid stopped early leaves its other nodes
    blank, never filled), the ε_safe contour, and each method's evaluated points (``overlays`` method -> (m, 2));
    ``worst`` marks each method's worst point (a star, in the legend only when one is drawn). ``bounds``: the box
    ``[(lo, hi), (lo, hi)]``; the axes then span the whole box, so that a title naming the box and the axes agree
    even where the grid covers only part of it. Axes named from :data:`AXIS_LABELS`."""
    fig, ax = new_fig(size=(7.2, 6.2))
    u0, u1 = np.unique(xs[:, 0]), np.unique(xs[:, 1])
    grid = np.full((len(u1), len(u0)), np.nan)
    i0 = np.searchsorted(u0, xs[:, 0])
    i1 = np.searchsorted(u1, xs[:, 1])
    finite = np.isfinite(fs)
    top = float(np.max(fs[finite])) if finite.any() else eps_safe_m
    grid[i1, i0] = np.where(finite, fs, top)  # a non-finite value: a failure, drawn at the top of the scale
    g = np.ma.masked_invalid(np.clip(grid, 1e-2, None))  # NaN: a node the grid never evaluated (blank)
    vmin = min(max(float(g.min()), 1e-2), eps_safe_m / 3)  # keep ε_safe inside the colour range
    vmax = max(float(g.max()), eps_safe_m * 1.5)
    im = ax.pcolormesh(u0, u1, g, shading="nearest", norm=LogNorm(vmin=vmin, vmax=vmax), cmap="viridis")
    cb = fig.colorbar(im, ax=ax)
    cb.set_label("position error L (m), log scale (values < 1 cm shown at 1 cm)")
    if len(u0) > 1 and len(u1) > 1 and g.max() > eps_safe_m > g.min():
        ax.contour(u0, u1, g, levels=[eps_safe_m], colors="#ff4040", linewidths=1.4)
    for m in method_order(overlays):
        pts = overlays[m]
        if len(pts):
            st = style(m)
            ax.scatter(pts[:, 0], pts[:, 1], s=14, marker=st["marker"], facecolors="none", edgecolors=st["color"],
                       linewidths=1.0, label=f"{st['label']} ({len(pts)} points)")
    stars = [(m, p) for m, p in (worst or {}).items() if p is not None]
    for m, p in stars:
        st = style(m)
        ax.scatter([p[0]], [p[1]], s=160, marker="*", color=st["color"], edgecolors="white", linewidths=0.8, zorder=5)
    ax.plot([], [], color="#ff4040", label=f"L = ε_safe = {eps_safe_m:g} m")
    if stars:  # a legend names only what is drawn
        ax.scatter([], [], s=100, marker="*", color="grey", label="worst point found")
    if bounds is not None:
        (x0, x1), (y0, y1) = bounds
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
    ax.set_xlabel(axis_label(names[0]))
    ax.set_ylabel(axis_label(names[1]))
    ax.set_title(wrapped(title, 5.6, 10), fontsize=10)
    fig.legend(fontsize=8, loc="outside lower center", ncol=3)
    return fig


def landscape_1d(xs: np.ndarray, fs: np.ndarray, name: str, overlays: Mapping[str, tuple[np.ndarray, np.ndarray]], *,
                 eps_safe_m: float, title: str) -> Figure:
    """L over a dense 1-D grid (line) with each method's evaluated points ``(x, f)`` on it (markers)."""
    fig, ax = new_fig(size=(8.0, 4.0))
    o = np.argsort(xs[:, 0])
    ax.plot(xs[o, 0], np.clip(fs[o], 1e-2, None), color="black", linewidth=1.0, label="dense grid")
    for m in method_order(overlays):
        px, pf = overlays[m]
        if len(px):
            st = style(m)
            ax.scatter(px[:, 0], np.clip(pf, 1e-2, None), s=18, marker=st["marker"], facecolors="none",
                       edgecolors=st["color"], label=f"{st['label']} ({len(px)} points)")
    ax.axhline(eps_safe_m, **EPS_STYLE, label=f"ε_safe = {eps_safe_m:g} m")
    ax.set_yscale("log")
    ax.set_xlabel(axis_label(name))
    ax.set_ylabel("position error L (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def best_vs_evals(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], *, eps_safe_m: float, title: str) -> Figure:
    """Median over images of the worst error found so far against evaluations, one line per method
    (``curves[method]`` = (evaluation counts, medians); every image counted at every count, so a curve never
    falls: :func:`vbl_robust.report.sections.progress_curves`)."""
    fig, ax = new_fig()
    for m, (n, best) in curves.items():
        st = style(m)
        # a marker where each curve starts (a search that reports once, in one batch, is a single point)
        ax.step(n, np.clip(best, 1e-2, None), where="post", color=st["color"], label=st["label"], linewidth=1.8,
                marker=st["marker"] or None, markevery=[0], markersize=6)
    ax.axhline(eps_safe_m, **EPS_STYLE, label=f"ε_safe = {eps_safe_m:g} m")
    ax.set_yscale("log")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("median over images of the worst error so far (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def survival_per_box(boxes: Sequence[Any], *, eps_safe_m: float, unit: str = "image",
                     title: str = "Survival per box") -> Figure:
    """The run's safety figure (its ``headline.png``): per box (:class:`vbl_robust.report.evidence.BoxEvidence`,
    every method together), the share of images that survive, are breached with a misleading pose and are breached
    with flagged failures only, stacked to 100 %, and survival's exact 95 % interval as a black bar; boxes from
    top to bottom in the order given (mildest first)."""
    shown = [b for b in boxes if b.images]
    fig, ax = new_fig(size=(7.2, 0.55 * len(shown) + 2.0))
    y = np.arange(len(shown))[::-1]
    parts = (("survivors", "survive", "#2ca02c"), ("misleading", "misleading breach", "#d62728"),
             ("flagged", "flagged-only breach", "#ff9f1c"))
    left = np.zeros(len(shown))
    for key, label, colour in parts:
        pct = np.array([100.0 * (getattr(b, key) or 0) / b.images for b in shown])
        ax.barh(y, pct, left=left, height=0.6, color=colour, label=label, alpha=0.85)
        left += pct
    unknown = 100.0 - left
    if np.any(unknown > 1e-9):
        ax.barh(y, unknown, left=left, height=0.6, color="#bdbdbd", label="breach of unknown kind")
    surv = np.array([100.0 * b.survivors / b.images for b in shown])
    lo = np.array([b.survival_ci[0] for b in shown])
    hi = np.array([b.survival_ci[1] for b in shown])
    ax.errorbar(surv, y, xerr=[np.clip(surv - lo, 0, None), np.clip(hi - surv, 0, None)], fmt="|", color="black",
                capsize=4, elinewidth=1.4, markersize=12, label="survival, 95 % interval")
    ax.set_yticks(y)
    ax.set_yticklabels([b.label for b in shown], fontsize=9)
    ax.set_xlim(0, 100)
    ax.set_ylim(-0.6, len(shown) - 0.4)
    ax.set_xlabel(f"{unit}s (%); one survives when no search found an error above ε_safe = {eps_safe_m:g} m")
    ax.grid(alpha=0.3, axis="x")
    n = max((b.images for b in shown), default=0)
    ax.set_title(f"{title}  [N = {n} {unit}s]", fontsize=10)
    fig.legend(fontsize=8, loc="outside lower center", ncol=4, frameon=False)
    return fig


def _family_text(p: Mapping[str, Any]) -> str:
    return levels_text(p["bounds"], p["unit"])


def _level_pos(p: Mapping[str, Any], level: float, beyond: int) -> float:
    """Position (1-based level index) of ``level`` among the entry's levels; ``beyond`` when not reached."""
    return float(beyond) if not math.isfinite(level) else float(list(p["levels"]).index(level) + 1)


def family_ranking(profile: Sequence[Mapping[str, Any]], order: Sequence[str], *, method: str = ANY_METHOD,
                   thresholds: Sequence[float] = (50.0, 10.0),
                   title: str = "Families ranked by the level where survival drops") -> Figure:
    """Families ranked (``order``: most vulnerable first, at the top) by the level index (1 = mild … 5 = extreme)
    at which the ``method`` series' survival drops below each of ``thresholds`` (one marker per threshold, joined
    by a line); "not reached" markers (hollow) sit in the shaded column right of the last level. Left tick labels
    name each family with its levels' ranges; right ones give its survival at its largest level."""
    rows = {p["family"]: p for p in profile if p["method"] == method}
    fams = [f for f in order if f in rows]
    n_levels = max((len(rows[f]["levels"]) for f in fams), default=5)
    beyond = n_levels + 1
    fig, ax = new_fig(size=(8.4, 0.42 * len(fams) + 1.9))
    ax.axvspan(beyond - 0.5, beyond + 0.5, color="grey", alpha=0.15)
    marks = (("o", "#1f77b4"), ("D", "#d62728"), ("s", "#2ca02c"), ("^", "#9467bd"))
    offsets = np.linspace(0.12, -0.12, len(thresholds)) if len(thresholds) > 1 else np.zeros(1)
    for i, f in enumerate(fams):
        p, y = rows[f], len(fams) - 1 - i
        xs = [_level_pos(p, p[f"below_{t:g}"], beyond) for t in thresholds]
        ax.plot(xs, [y + o for o in offsets], color="grey", linewidth=1.0, zorder=2)
        for x, o, (mk, c) in zip(xs, offsets, marks, strict=False):
            hollow = x == beyond
            ax.scatter([x], [y + o], marker=mk, s=46, zorder=3, facecolors="none" if hollow else c, edgecolors=c,
                       linewidths=1.3)
    ax.set_yticks(range(len(fams)))
    ax.set_yticklabels([f"{f}  ({_family_text(rows[f])})" for f in reversed(fams)], fontsize=8)
    ax.set_ylim(-0.6, len(fams) - 0.4)
    ax.set_xticks(range(1, beyond + 1))
    ax.set_xticklabels([f"L{k}" for k in range(1, beyond)] + ["not\nreached"])
    ax.set_xlim(0.5, beyond + 0.5)
    ax.set_xlabel("budget level (1 = mild … 5 = extreme; ranges per family in the labels)")
    ax.grid(alpha=0.3, axis="x")
    right = ax.twinx()
    right.set_ylim(ax.get_ylim())
    right.set_yticks(range(len(fams)))
    right.set_yticklabels([f"{rows[f]['survival'][-1]:.0f} %" if math.isfinite(rows[f]["survival"][-1]) else "–"
                           for f in reversed(fams)], fontsize=8)
    right.set_ylabel("survival at the largest level", fontsize=8)
    n = max((max(rows[f]["n"], default=0) for f in fams), default=0)
    ax.set_title(f"{title}\n({style(method)['label']}, N = {n} images; most vulnerable at the top)", fontsize=10)
    handles = [Line2D([], [], marker=mk, color=c, linestyle="", label=f"survival < {t:g} %")
               for (mk, c), t in zip(marks, thresholds, strict=False)]
    handles.append(Patch(facecolor="grey", alpha=0.15, label="not reached (hollow)"))
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=len(handles))
    return fig


def family_survival(profile: Sequence[Mapping[str, Any]], order: Sequence[str], *, ncols: int = 5,
                    title: str = "Survival vs budget level, per perturbation family") -> Figure:
    """Small multiples, one panel per family in ``order``: survival (%) against the level index, one line per
    method, the dense-grid reference (black dashes) and the combined series (grey dots); 50 % and 10 % marked.
    Each panel's title gives the family's levels in its unit."""
    fams = [f for f in order if any(p["family"] == f for p in profile)]
    ncols = max(1, min(ncols, len(fams)))
    nrows = max(1, math.ceil(len(fams) / ncols))
    fig, axes = new_fig(nrows, ncols, size=(2.9 * ncols, 2.5 * nrows + 0.9), squeeze=False, sharey=True)
    handles: dict[str, Any] = {}
    for ax, f in zip(axes.flat, fams, strict=False):
        series = [p for p in profile if p["family"] == f]
        ms = method_order(q["method"] for q in series)
        searches = [m for m in ms if m not in (REFERENCE, ANY_METHOD)]
        for p in sorted(series, key=lambda p: ms.index(p["method"])):
            st = style(p["method"])
            # searches a little apart, so that coinciding curves stay visible
            dx = 0.06 * (searches.index(p["method"]) - (len(searches) - 1) / 2) if p["method"] in searches else 0.0
            x = np.arange(1, len(p["levels"]) + 1) + dx
            (line,) = ax.plot(x, p["survival"], marker=st["marker"] or None, color=st["color"],
                              linestyle=st["linestyle"], markersize=4, linewidth=1.4, label=st["label"])
            handles.setdefault(st["label"], line)
        for t in (50, 10):
            ax.axhline(t, color="grey", linestyle=":", linewidth=0.9)
        n = len(series[0]["levels"])
        ax.set_xticks(range(1, n + 1))
        ax.set_xticklabels([f"L{k}" for k in range(1, n + 1)], fontsize=8)
        ax.set_xlim(0.7, n + 0.3)
        ax.set_ylim(-3, 103)
        ax.set_title(f"{f}\n{_family_text(series[0])}", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(fams):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("survival S_rate (%)", fontsize=8)
    fig.legend(list(handles.values()), list(handles), fontsize=8, loc="outside lower center", ncol=len(handles))
    fig.suptitle(title)
    return fig



def risk_per_image(series: Mapping[str, Sequence[tuple[int, float, float, float]]], n_images: int,
                   tau: float) -> Figure:
    """Each image's failure probability with its interval, one series per estimator: ``series[method]`` = (image
    position, p_fail, low, high) as fractions, drawn in %; the dashed line is ``tau``."""
    fig, ax = new_fig(size=(8.0, 3.8))
    for j, (m, pts) in enumerate(series.items()):
        if not pts:
            continue
        x, p, lo, hi = (np.asarray(v, dtype=np.float64) for v in zip(*pts, strict=True))
        ax.errorbar(x + 0.15 * (j - (len(series) - 1) / 2), 100 * p, yerr=np.clip([100 * (p - lo), 100 * (hi - p)], 0,
                                                                                    None),
                    fmt="o", capsize=2, markersize=4, label=m)
    ax.axhline(100 * tau, **{**EPS_STYLE, "color": "grey"}, label=f"τ = {100 * tau:g} %")
    ax.set_xticks(range(n_images))
    ax.set_xticklabels([str(i + 1) for i in range(n_images)], fontsize=7)
    ax.set_xlabel("image (in the table's order)")
    ax.set_ylabel("p_fail (%), with its interval")
    ax.set_title("Failure probability per image")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig
