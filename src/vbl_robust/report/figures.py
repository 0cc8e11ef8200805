"""The report's figures (matplotlib, Agg): one function per paper figure, each taking metric tables.

Every function returns a :class:`matplotlib.figure.Figure` (the caller saves and closes it). Conventions shared
by all: survival rate in %, errors in metres, ε_safe drawn as a dashed red line, one colour and marker per
method (:data:`STYLE`), the dense-grid reference (true worst case up to the grid spacing) in black dashes.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from ..campaigns.metrics import ANY_METHOD, Summary  # noqa: E402
from ..campaigns.metrics import REFERENCE_METHOD as REFERENCE  # noqa: E402
from ..search.zones import BREACHED, CLASSES, RULED_OUT, UNDECIDED, ZoneMap  # noqa: E402

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
AXIS_LABELS = {"roll_deg": "roll φ (°)", "contrast": "contrast factor α"}
EPS_STYLE = {"color": "#d62728", "linestyle": ":", "linewidth": 1.2}


def style(method: str) -> dict[str, Any]:
    """Plot style of a method (a grey default for unknown names); its label is the optimizer class's."""
    from ..search import METHODS

    s = STYLE.get(method, {"color": "grey", "marker": "x"})
    label = s.get("label") or (METHODS[method].label if method in METHODS else method)
    return {"linestyle": "-", **s, "label": label}


def method_order(methods: Iterable[str]) -> list[str]:
    """The distinct ``methods`` in plotting order (the order of :data:`STYLE`, the reference and the combined
    series last)."""
    ms = list(dict.fromkeys(methods))
    return sorted(ms, key=lambda m: (m in (REFERENCE, ANY_METHOD), list(STYLE).index(m) if m in STYLE else 99, m))


_PLAIN = FuncFormatter(lambda v, _: f"{v:g}")


def _plain_log_axis(axis: Any) -> None:
    """Plain numbers (1000, 1500) instead of 1.5×10³ on a log axis."""
    axis.set_major_formatter(_PLAIN)
    axis.set_minor_formatter(_PLAIN)


def _fig(nrows: int = 1, ncols: int = 1, size: tuple[float, float] = (6.4, 4.0), **kw: Any) -> tuple[Figure, Any]:
    fig, ax = plt.subplots(nrows, ncols, figsize=size, layout="constrained", **kw)
    return fig, ax


def _ci_bars(rows: Sequence[Summary]) -> np.ndarray:
    """``(2, N)`` distances from each row's survival % down and up to its exact 95 % interval (error bars)."""
    cis = [r.survival_rate.ci for r in rows]
    return np.array([[max(r.survival - c.low, 0.0) for r, c in zip(rows, cis, strict=True)],
                     [max(c.high - r.survival, 0.0) for r, c in zip(rows, cis, strict=True)]]).reshape(2, len(rows))


def survival_vs_level(summary: Sequence[Summary], *, title: str, xlabel: str,
                      tick_labels: Mapping[float, str] | None = None) -> Figure:
    """Survival rate (%) against the perturbation budget (box level), one line per method (+ grid reference),
    each point with its exact 95 % interval as an error bar.

    Budgets are placed at equal spacing (categories, as in the paper) and methods are offset slightly
    sideways so that coinciding curves and their bars stay visible.
    """
    fig, ax = _fig()
    levels = sorted({r.box_level for r in summary})
    pos = {v: i for i, v in enumerate(levels)}
    methods = method_order(r.method for r in summary)
    for j, m in enumerate(methods):
        rs = sorted((r for r in summary if r.method == m), key=lambda r: r.box_level)
        st = style(m)
        dx = 0.0 if m == REFERENCE else 0.07 * (j - (len(methods) - 2) / 2)
        ax.errorbar([pos[r.box_level] + dx for r in rs], [r.survival for r in rs], yerr=_ci_bars(rs),
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
    fig, ax = _fig()
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
    fig, (a1, a2) = _fig(1, 2, size=(10.5, 4.4))
    rows = [r for r in summary if math.isfinite(r.budget(axis))]
    for m in method_order(r.method for r in rows):
        rs = sorted((r for r in rows if r.method == m), key=lambda r: r.budget(axis))
        st = style(m)
        x = [r.budget(axis) for r in rs]
        kw = {"marker": st["marker"], "color": st["color"], "label": st["label"], "linewidth": 1.8}
        a1.errorbar(x, [r.survival for r in rs], yerr=_ci_bars(rs), elinewidth=0.8, capsize=2, **kw)
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
        _plain_log_axis(a2.yaxis)
    a2.set_ylabel("median worst error over images (m)")
    fig.legend(*a2.get_legend_handles_labels(), fontsize=8, loc="outside lower center", ncol=5)
    fig.suptitle(title)
    return fig


def pnp_comparison(summary: Sequence[Mapping[str, Any]]) -> Figure:
    """Median and mean (MAE) relative position error per PnP solver (over its successful solves), for the
    ground-truth and the detector keypoints; tick labels give each solver's failure count."""
    sources = list(dict.fromkeys(r["source"] for r in summary))
    fig, axes = _fig(1, len(sources), size=(3.8 * len(sources), 4.2), squeeze=False)
    for k, (ax, src) in enumerate(zip(axes[0], sources, strict=True)):
        rs = [r for r in summary if r["source"] == src]
        x = np.arange(len(rs))
        ax.bar(x - 0.2, [r["median_rel_pct"] for r in rs], 0.4, label="median", color="#1f77b4")
        ax.bar(x + 0.2, [r["mae_rel_pct"] for r in rs], 0.4, label="mean (MAE)", color="#ff7f0e")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{r['solver']}\n{r['failures']}/{r['n']} failed" for r in rs], fontsize=8)
        vals = np.asarray([r[k] for r in rs for k in ("median_rel_pct", "mae_rel_pct")], dtype=float)
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


def distance_profile(profile: Sequence[Mapping[str, Any]], *, limit_deg: float, budgets: Sequence[float],
                     title: str = "Vulnerability profile by approach distance") -> Figure:
    """Left: φ_crit (roll budget dropping survival below 10 %) per slant-distance quartile, one bar per method;
    hatched bars in the red band ≥ ``limit_deg`` = no φ_crit within the limit. Right: survival rate against the
    roll budget per quartile for the first method (solid) and the dense-grid reference (dashed) if present."""
    fig, (ax, a2) = _fig(1, 2, size=(11.5, 4.8), gridspec_kw={"width_ratios": [1.25, 1]})
    quartiles = sorted({r["quartile"] for r in profile})
    methods = method_order(p["method"] for p in profile)
    width = 0.8 / max(len(methods), 1)
    top = limit_deg * 1.12
    ax.axhspan(limit_deg, top, color="#d62728", alpha=0.15)
    handles = [Patch(facecolor="#d62728", alpha=0.15, label=f"≥ {limit_deg:g}° (hatched): no φ_crit within the limit")]
    for i, m in enumerate(methods):
        st = style(m)
        rs = {r["quartile"]: r for r in profile if r["method"] == m}
        xs = [q + (i - (len(methods) - 1) / 2) * width for q in quartiles]
        vals = [rs[q]["phi_crit"] if q in rs else math.nan for q in quartiles]
        for x, v in zip(xs, vals, strict=True):
            beyond = not math.isfinite(v)
            ax.bar(x, limit_deg * 1.06 if beyond else v, width * 0.9, color=st["color"], alpha=0.85,
                   hatch="//" if beyond else None, edgecolor="white")
            if not beyond:
                ax.annotate(f"{v:g}°", (x, v), ha="center", va="bottom", fontsize=7)
        handles.append(Patch(facecolor=st["color"], label=st["label"]))
    first = [r for r in profile if r["method"] == methods[0]] if methods else []
    lab = {r["quartile"]: f"Q{r['quartile']}\n{r['d_min_m'] / 1000:.1f}–{r['d_max_m'] / 1000:.1f} km\n(n={r['n']})" for r in first}
    ax.set_xticks(quartiles)
    ax.set_xticklabels([lab.get(q, f"Q{q}") for q in quartiles], fontsize=8)
    ax.set_ylim(0, top)
    ax.set_yticks([b for b in budgets if b <= limit_deg])
    ax.set_ylabel("φ_crit: roll budget for S_rate < 10 % (°)")
    ax.set_xlabel("slant-distance quartile (closest first)")
    ax.set_title("critical roll per quartile", fontsize=10)
    ax.grid(alpha=0.3, axis="y")
    fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncol=len(handles))
    colors = plt.get_cmap("viridis")(np.linspace(0.0, 0.85, max(len(quartiles), 1)))
    shown = [m for m in methods if m != REFERENCE][:1] + [m for m in methods if m == REFERENCE]
    for q, c in zip(quartiles, colors, strict=True):
        for m in shown:
            r = next((r for r in profile if r["method"] == m and r["quartile"] == q), None)
            if r is not None:
                a2.plot(budgets, r["survival"], color=c, linestyle="--" if m == REFERENCE else "-", marker="o",
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


def convergence(conv: Sequence[Mapping[str, Any]], *, title: str = "GeoRobust convergence (roll ±15°)") -> Figure:
    """Top: |PO_k| per iteration; bottom: RA(k) in %. Median (line), interquartile range and 10–90th percentile
    (bands), mean (dotted) over images — percentiles, because a few images with a flat region (every box ties)
    have PO sets orders of magnitude larger than the rest."""
    fig, (a1, a2) = _fig(2, 1, size=(6.4, 6.2), sharex=True)
    k = np.array([r["iteration"] for r in conv])
    for ax, name, ylabel in ((a1, "po", "|PO_k| (potentially optimal boxes)"), (a2, "ra", "RA(k): remaining area (%)")):
        def col(key: str, name: str = name) -> np.ndarray:
            return np.array([r.get(f"{name}_{key}", np.nan) for r in conv], dtype=np.float64)

        ax.fill_between(k, col("q10"), col("q90"), color="#1f77b4", alpha=0.12, label="10–90th percentile")
        ax.fill_between(k, col("q25"), col("q75"), color="#1f77b4", alpha=0.3, label="25–75th percentile")
        ax.plot(k, col("median"), color="#1f77b4", marker="o", markersize=3, label="median")
        ax.plot(k, col("mean"), color="#d62728", linestyle=":", linewidth=1.2, label="mean")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    hi = np.nanmax([r.get("po_max", r["po_mean"]) for r in conv]) if conv else 1.0
    if hi > 60:
        a1.set_yscale("log")
        a1.yaxis.set_major_formatter(_PLAIN)
    a2.axhline(20, color="grey", linestyle="--", linewidth=1, label="20 % (paper: reached by k = 10)")
    a2.axvline(10, color="grey", linestyle=":", linewidth=1)
    a2.set_ylim(0, 105)
    a2.set_xlabel("iteration k (k = 1: the whole box)")
    a1.legend(fontsize=8)
    a2.legend(fontsize=8)
    n = max((r["n"] for r in conv), default=0)
    fig.suptitle(f"{title}, N = {n} images")
    return fig


def landscape_2d(xs: np.ndarray, fs: np.ndarray, names: Sequence[str], overlays: Mapping[str, np.ndarray], *,
                 eps_safe_m: float, title: str, worst: Mapping[str, np.ndarray] | None = None) -> Figure:
    """Heat map of L over a complete 2-D grid (``xs`` (n, 2), ``fs`` (n,)), the ε_safe contour, and each
    method's evaluated points (``overlays`` method -> (m, 2)); ``worst`` marks each method's worst point."""
    fig, ax = _fig(size=(7.2, 6.2))
    u0, u1 = np.unique(xs[:, 0]), np.unique(xs[:, 1])
    grid = np.full((len(u1), len(u0)), np.nan)
    i0 = np.searchsorted(u0, xs[:, 0])
    i1 = np.searchsorted(u1, xs[:, 1])
    grid[i1, i0] = fs
    g = np.clip(np.where(np.isfinite(grid), grid, np.nanmax(grid)), 1e-2, None)
    vmin = min(max(float(np.nanmin(g)), 1e-2), eps_safe_m / 3)  # keep ε_safe inside the colour range
    vmax = max(float(np.nanmax(g)), eps_safe_m * 1.5)
    im = ax.pcolormesh(u0, u1, g, shading="nearest", norm=LogNorm(vmin=vmin, vmax=vmax), cmap="viridis")
    cb = fig.colorbar(im, ax=ax)
    cb.set_label("position error L (m), log scale (values < 1 cm shown at 1 cm)")
    if np.nanmax(g) > eps_safe_m > np.nanmin(g):
        ax.contour(u0, u1, g, levels=[eps_safe_m], colors="#ff4040", linewidths=1.4)
    for m in method_order(overlays):
        pts = overlays[m]
        if len(pts):
            st = style(m)
            ax.scatter(pts[:, 0], pts[:, 1], s=14, marker=st["marker"], facecolors="none", edgecolors=st["color"],
                       linewidths=1.0, label=f"{st['label']} ({len(pts)} points)")
    for m, p in (worst or {}).items():
        if p is not None:
            st = style(m)
            ax.scatter([p[0]], [p[1]], s=160, marker="*", color=st["color"], edgecolors="white", linewidths=0.8, zorder=5)
    ax.plot([], [], color="#ff4040", label=f"L = ε_safe = {eps_safe_m:g} m")
    ax.scatter([], [], s=100, marker="*", color="grey", label="worst point found")
    ax.set_xlabel(AXIS_LABELS.get(names[0], names[0]))
    ax.set_ylabel(AXIS_LABELS.get(names[1], names[1]))
    ax.set_title(title, fontsize=10)
    fig.legend(fontsize=8, loc="outside lower center", ncol=3)
    return fig


def landscape_1d(xs: np.ndarray, fs: np.ndarray, name: str, overlays: Mapping[str, tuple[np.ndarray, np.ndarray]], *,
                 eps_safe_m: float, title: str) -> Figure:
    """L over a dense 1-D grid (line) with each method's evaluated points ``(x, f)`` on it (markers)."""
    fig, ax = _fig(size=(8.0, 4.0))
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
    ax.set_xlabel(AXIS_LABELS.get(name, name))
    ax.set_ylabel("position error L (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def best_vs_evals(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], *, eps_safe_m: float, title: str) -> Figure:
    """Median over images of the best error found so far against evaluations, one line per method."""
    fig, ax = _fig()
    for m, (n, best) in curves.items():
        st = style(m)
        ax.step(n, np.clip(best, 1e-2, None), where="post", color=st["color"], label=st["label"], linewidth=1.8)
    ax.axhline(eps_safe_m, **EPS_STYLE, label=f"ε_safe = {eps_safe_m:g} m")
    ax.set_yscale("log")
    ax.set_xlabel("evaluations")
    ax.set_ylabel("median over images of the worst error so far (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _family_text(p: Mapping[str, Any]) -> str:
    from ..campaigns.experiments import levels_text

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
    fig, ax = _fig(size=(8.4, 0.42 * len(fams) + 1.9))
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
    fig, axes = _fig(nrows, ncols, size=(2.9 * ncols, 2.5 * nrows + 0.9), squeeze=False, sharey=True)
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


# -- vulnerability zones -------------------------------------------------------------------------------------------
COLOURS = {BREACHED: "#d62728", UNDECIDED: "#bdbdbd", RULED_OUT: "#2ca02c"}


def plot_zones(zone_map: ZoneMap, path: str | Path, *, landscape: tuple[np.ndarray, np.ndarray] | None = None,
               title: str | None = None) -> Path:
    """Draw the zones of a 1-D or 2-D box to a PNG and return the path.

    1-D: the cells as coloured bands under the values at their centres, with ε (and ``landscape = (xs (n, 1),
    fs (n,))``, e.g. a dense grid, as a line). 2-D: the cells as coloured rectangles and their centres (with a
    ``landscape = (xs (n, 2), fs (n,))``: its values as a log-scale heat map under the rectangles, which are then
    drawn translucent with edges of their class's colour, and its ε contour). ValueError for more than two
    parameters or a landscape of another dimension."""
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
    label = lambda i: f"{box.names[i]}" + (f" ({box.units[i]})" if box.units[i] else "")  # noqa: E731
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
    ax.set_title(title or f"{zone_map.method}: zones ({basis[zone_map.basis]})", fontsize=9)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


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
        im = ax.pcolormesh(u0, u1, np.ma.masked_invalid(grid), shading="nearest", norm=norm, cmap="viridis")
        if np.nanmin(grid) < threshold < np.nanmax(grid):
            ax.contour(u0, u1, np.ma.masked_invalid(grid), levels=[threshold], colors="white", linewidths=1.2,
                       linestyles="--")
    else:
        im = ax.scatter(xs[finite, 0], xs[finite, 1], c=v[finite], norm=norm, cmap="viridis", s=8)
    fig.colorbar(im, ax=ax).set_label(f"landscape value (log scale; dashed: ε = {threshold:g})", fontsize=8)


def risk_per_image(series: Mapping[str, Sequence[tuple[int, float, float, float]]], n_images: int,
                   tau: float) -> Figure:
    """Each image's failure probability with its interval, one series per estimator: ``series[method]`` = (image
    position, p_fail, low, high) as fractions, drawn in %; the dashed line is ``tau``."""
    fig, ax = _fig(size=(8.0, 3.8))
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
    fig, axes = _fig(1, 2, size=(6.4, 3.6))
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
