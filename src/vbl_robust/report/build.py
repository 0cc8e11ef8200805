"""Assemble the HTML report of a run directory from its results store (``vbl-robust report RUN``).

The report is rebuilt from the store alone: every figure is drawn from the stored rows, every figure comes with
the table of the numbers behind it, and the provenance of every run (code version, model SHA-256, dataset
identity, configuration) closes the page. Figures are also written as PNG files next to the report.

Which figures: the ones the campaign spec declares (``CampaignSpec.figures``, see
:data:`vbl_robust.campaigns.spec.FIGURES`; a spec stored without a declaration gets
:func:`~vbl_robust.campaigns.spec.default_figures` of its blocks), each drawn by its entry of :data:`SECTIONS`
from the rows it needs; a declared figure without data is left out. The summary always shows the failed
evaluations (``n_failed``) and their counts per failure reason.

Vulnerability zones (:func:`section_zones`, after the landscape) need no declaration: a run with main jobs of a
method that keeps a cover of its box (DIRECT family, grid) gets them. Each such job is replayed on its stored
values (:func:`vbl_robust.campaigns.replay.job_zones`: no evaluation) and classified sound under the run's Lipschitz
constant, else on the method's own estimate (labelled "not sound"); the landscape image's jobs are drawn over its
landscape (:func:`vbl_robust.report.figures.plot_zones`), and a table gives the fractions of Θ per class over all jobs.
A job whose replay fails is listed as skipped, with the reason.

Budgets read off a trace (the runtime experiments' anytime methods): the main rows are derived per read budget
from the stored runs (:func:`vbl_robust.campaigns.metrics.read_off_rows`), and every table that shows them has a
column "read off the run" naming the run they were read from; results of runs of their own leave it empty.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from ..campaigns import metrics as mx
from ..campaigns.experiments import EXPERIMENTS, range_text
from ..campaigns.replay import JobZones, ReplayError, job_zones
from ..campaigns.spec import FIGURES, BoxSpec, CampaignSpec
from ..campaigns.store import JobRow, JobStatus, ResultStore
from ..constants import FAILURE_REASONS, Verdict
from ..report.figures import plot_zones
from ..search import METHODS, NON_FINITE
from ..search.zones import CLASSES, ZoneMap
from . import figures as F
from .html import esc, figure_png, fmt_num, img, page, table

logger = logging.getLogger(__name__)


@dataclass
class Section:
    title: str
    html: list[str] = field(default_factory=list)


@dataclass
class Context:
    """What every section builder needs: the stored rows, the spec and where figures go."""

    store: ResultStore
    spec: CampaignSpec
    out_dir: Path
    main: list[JobRow]
    samples: dict[str, dict[str, Any]]
    figures: list[Path] = field(default_factory=list)

    @property
    def eps(self) -> float:
        return self.spec.eps_safe_m

    @cached_property
    def runs(self) -> list[JobRow]:
        """The stored main search jobs with their points (as run: no rows read off a trace)."""
        return self.store.jobs(kind="search", role="main", with_points=True, with_trace=False)

    def figure(self, fig: Any, name: str, caption: str) -> str:
        png = figure_png(fig)
        plt.close(fig)
        path = self.out_dir / "figures" / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(png)
        self.figures.append(path)
        return img(png, name, caption)

    def figure_file(self, path: Path, name: str, caption: str) -> str:
        """A PNG already written under ``figures/`` (e.g. by :func:`vbl_robust.report.figures.plot_zones`), embedded."""
        self.figures.append(path)
        return img(path.read_bytes(), name, caption)


_SUMMARY_COLS = [
    ("method", "method", None), ("box_label", "box", None), ("budget_label", "budget per image", None),
    ("n", "images", None), ("survival", "survival %", None), ("median_worst_m", "median worst (m)", None),
    ("breaches", "breaches", None), ("certified", "certified", None), ("failed", "failed", None),
    ("mean_nfev", "mean evals", None), ("failed_evals", "failed evals", None), ("median_search_s", "median s", None),
]


def _summary_table(summary: Sequence[Mapping[str, Any]]) -> str:
    cols = list(_SUMMARY_COLS)
    if any(line.get("read_from") for line in summary):
        cols.append(("read_from", "read off the run", None))
    return table(summary, cols, left=("method", "box_label", "budget_label", "read_from"))


def _failures_table(summary: Sequence[Mapping[str, Any]], penalty_m: float) -> str:
    """Failed evaluations per reason and group (the search used the penalty for them), with the codes' meaning."""
    codes = sorted({c for line in summary for c in line["failures"]})
    if not codes:
        return ""
    lines = [{**line, **{f"reason:{c}": line["failures"].get(c, 0) for c in codes}} for line in summary]
    cols = [("method", "method", None), ("box_label", "box", None), ("budget_label", "budget per image", None),
            ("nfev", "evaluations", None), ("failed_evals", "failed", None),
            *[(f"reason:{c}", c, None) for c in codes]]
    meaning = {**FAILURE_REASONS, NON_FINITE: "the objective returned NaN or ±inf"}
    legend = "; ".join(f"<code>{esc(c)}</code>: {esc(meaning.get(c, c))}" for c in codes)
    return (f"<p>Failed evaluations by reason (each counts in the search with the {penalty_m:g} m penalty): "
            f"{legend}.</p>" + table(lines, cols, left=("method", "box_label", "budget_label")))


def _reference(ctx: Context, boxes: Sequence[BoxSpec]) -> list[JobRow]:
    ref = ctx.store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
    return mx.reference_rows(ref, boxes, ctx.eps, ctx.spec.penalty_m)


def _main_boxes(ctx: Context) -> list[BoxSpec]:
    seen: dict[str, BoxSpec] = {}
    for r in ctx.main:
        if r.box is not None:
            seen.setdefault(r.box.label, r.box)
    return list(seen.values())


# -- sections ------------------------------------------------------------------------------------------------
def section_overview(ctx: Context, title: str) -> Section:
    s = Section("Summary")
    runs = ctx.store.runs()
    last = runs[-1] if runs else {}
    det = (last.get("detector") or {})
    n_done = ctx.store.count()
    total = last.get("jobs_total")
    s.html.append(
        f"<p><b>{esc(title)}</b>. Detector: <b>{esc(det.get('name', '?'))}</b>; {len(ctx.samples)} images; "
        f"ε_safe = {ctx.eps:g} m, τ_conf = {ctx.spec.conf_threshold:g}, failure penalty {ctx.spec.penalty_m:g} m, "
        f"PnP solver <code>{esc(ctx.spec.pnp)}</code>, seed {ctx.spec.seed}. Jobs in the store: {n_done}"
        + (f" of {total}" if total else "") + ".</p>")
    if ctx.spec.notes:
        s.html.append(f'<p class="note">{esc(ctx.spec.notes)}</p>')
    for goal in det.get("open_goals") or []:
        s.html.append(f'<p class="warn">Open accuracy goal of this detector (its model card): {esc(goal)}.</p>')
    if det.get("kind") == "oracle":
        s.html.append('<p class="warn">The oracle detector returns the exact projected runway corners: these results '
                      "describe a perfect detector (roll about the optical axis does not move the camera), not a "
                      "trained model.</p>")
    if total and n_done < total:
        s.html.append(f'<p class="warn">The campaign is incomplete ({n_done} of {total} jobs): rerun the same '
                      "command to resume.</p>")
    if ctx.main:
        summary = mx.summarize(ctx.main, ctx.eps)
        s.html.append(_summary_table(summary))
        s.html.append(_failures_table(summary, ctx.spec.penalty_m))
    failed = [r for r in ctx.store.jobs(with_trace=False) if r.status is JobStatus.FAILED]
    if failed:
        s.html.append(f'<p class="warn">{len(failed)} job(s) failed and count with the {ctx.spec.penalty_m:g} m '
                      "penalty (never as survivors):</p>")
        lines = [{"sample_id": r.sample_id, "method": r.method, "box_label": r.box_label, "reason": r.reason}
                 for r in failed[:50]]
        s.html.append(table(lines, [("sample_id", "sample", None), ("method", "method", None),
                                    ("box_label", "box", None), ("reason", "reason", None)],
                            left=("sample_id", "method", "box_label", "reason")))
    return s


def section_survival_level(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.chain is None]
    if len({r.box_level for r in rows}) < 2:
        return None
    boxes = _main_boxes(ctx)
    summary = mx.summarize(rows, ctx.eps, by=("method", "box_label"))
    ref = mx.summarize(_reference(ctx, boxes), ctx.eps, by=("method", "box_label"))
    two_d = any(b.box.dim > 1 for b in boxes)
    ticks = {b.level: b.label for b in boxes} if two_d else None
    title = "Survival vs roll and contrast budget" if two_d else "Survival vs roll budget"
    s = Section(title)
    fig = F.survival_vs_level(summary + ref, title=title, tick_labels=ticks,
                              xlabel="perturbation box (roll half-width, contrast range)" if two_d else "roll budget")
    s.html.append(ctx.figure(fig, "survival_2d" if two_d else "survival_1d",
                             "Survival rate S_rate: share of images whose worst error found stays ≤ ε_safe. Lower "
                             "means the search found more breaches (a stronger search)."))
    s.html.append(_summary_table(summary + ref))
    return s


def section_runtime(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.budget is not None]
    time_rows = [r for r in rows if r.budget.max_seconds is not None]
    eval_rows = [r for r in rows if r.budget.max_seconds is None and r.budget.max_evals is not None]
    if len({r.budget_label for r in time_rows}) < 2 and len({r.budget_label for r in eval_rows}) < 2:
        return None
    boxes = _main_boxes(ctx)
    ref_rows = _reference(ctx, boxes)
    ref = None
    if ref_rows:
        w = [r.worst_m for r in ref_rows]
        ref = {"survival": mx.survival_rate(w, ctx.eps), "median_worst_m": float(np.median(w))}
    box_label = boxes[0].label if boxes else ""
    s = Section(f"Runtime budgets ({box_label})")
    for axis, rs, name in (("max_seconds", time_rows, "time"), ("max_evals", eval_rows, "evals")):
        if len({r.budget_label for r in rs}) < 2:
            continue
        summary = mx.summarize(rs, ctx.eps, by=("method", "budget_label"))
        for line in summary:
            line["box_label"] = box_label
        dims = "2d" if boxes and boxes[0].box.dim > 1 else "1d"
        fig = F.runtime(summary, axis=axis, eps_safe_m=ctx.eps, reference=ref,
                        title=f"{'Time' if axis == 'max_seconds' else 'Evaluation'} budget per image, box {box_label}")
        s.html.append(ctx.figure(fig, f"runtime_{dims}_{name}",
                                 "Left: survival rate; right: median over images of the worst error found "
                                 "(no early stop). Dashed black: the dense grid's true worst case."))
        s.html.append(_summary_table(summary))
    read = sorted({r.method for r in rows if r.read_from})
    if read:
        own = sorted({r.method for r in rows if not r.read_from})
        s.html.append(f'<p class="note">Read off a trace: {esc(", ".join(read))} ran once per image (budget '
                      f"{esc(next(r.read_from for r in rows if r.read_from))}); each time budget t counts only the "
                      "evaluations completed by t, each evaluation budget n the run's first n evaluations."
                      + (f" Run once per budget: {esc(', '.join(own))}." if own else "") + "</p>")
    if ref:
        s.html.append(f"<p>Dense-grid reference on {len(ref_rows)} images: survival {fmt_num(ref['survival'])} %, "
                      f"median worst {fmt_num(ref['median_worst_m'])} m.</p>")
    return s


def section_distance(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.chain is not None]
    if not rows:
        return None
    distances = {sid: s["slant_distance_m"] for sid, s in ctx.samples.items()}
    budgets = sorted({r.box_level for r in rows})
    limit = max(budgets)
    ref = _reference(ctx, _main_boxes(ctx))
    profile = mx.distance_profile(rows + ref, distances, budgets)
    s = Section("Vulnerability profile by approach distance")
    fig = F.distance_profile(profile, limit_deg=limit, budgets=budgets)
    s.html.append(ctx.figure(fig, "distance_profile",
                             "φ_crit per slant-distance quartile: the smallest roll budget at which the quartile's "
                             f"survival drops below 10 %. Bars in the red band: survival never dropped below 10 % "
                             f"within ±{limit:g}°."))
    lines = [{**p, "survival_str": " / ".join(fmt_num(v) for v in p["survival"]),
              "phi": f"≥ {limit:g}°" if not math.isfinite(p["phi_crit"]) else f"{p['phi_crit']:g}°",
              "range": f"{p['d_min_m']:.0f}–{p['d_max_m']:.0f}"} for p in profile]
    s.html.append(table(lines, [("quartile", "quartile", None), ("range", "slant distance (m)", None),
                                ("method", "method", None), ("n", "images", None), ("n_breached", "breached ≤ limit", None),
                                ("median_level", "median smallest breaching budget (°)", None), ("phi", "φ_crit", None),
                                ("survival_str", f"survival % at {', '.join(f'{b:g}' for b in budgets)}°", None)],
                        left=("method", "survival_str")))
    return s


def _level_name(p: Mapping[str, Any], level: float) -> str:
    """``"L3 (±10°)"``: the level's index and range; "not reached" for ``inf``."""
    if not math.isfinite(level):
        return "not reached"
    k = list(p["levels"]).index(level)
    return f"L{k + 1} ({range_text(*p['bounds'][k], p['unit'])})"


def family_lines(profile: Sequence[Mapping[str, Any]], order: Sequence[str]) -> list[dict[str, Any]]:
    """The families table: per family (in ranking ``order``) and method (plot order, the combined series last),
    the rank, images, survival % at each level (``L1`` … ``L5``) and the levels where it drops below 50 % and
    10 %."""
    lines = []
    for rank, fam in enumerate(order, start=1):
        series = {p["method"]: p for p in profile if p["family"] == fam}
        for m in F.method_order(series):
            p = series[m]
            line: dict[str, Any] = {"rank": rank, "family": fam, "method": F.style(m)["label"],
                                    "n": max(p["n"], default=0)}
            line.update({f"L{k}": v for k, v in enumerate(p["survival"], start=1)})
            for t in mx.RANK_THRESHOLDS:
                line[f"below_{t:g}"] = _level_name(p, p[f"below_{t:g}"])
            lines.append(line)
    return lines


def section_families(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if mx.family_of(r) is not None]
    if not rows:
        return None
    ref = _reference(ctx, _main_boxes(ctx))
    profile = mx.family_profile(rows + ref, ctx.eps)
    order = mx.rank_families(profile)
    s = Section("Perturbation families: survival vs budget level")
    s.html.append(ctx.figure(F.family_ranking(profile, order), "families_ranking",
                             "Each family alone, ranked by the budget level at which survival drops below 50 % "
                             "(circle) and below 10 % (diamond), most vulnerable first; an image survives a level "
                             "when no method, the dense grid included, found a breach (L > ε_safe) within it. "
                             "Hollow markers in the grey column: not reached at the largest level."))
    s.html.append(ctx.figure(F.family_survival(profile, order), "families_survival",
                             "Survival against the level index per family and method (levels nested, chained per "
                             "image: a breach at a level counts at every larger one). Black dashes: the dense "
                             "grid's true survival up to its spacing; grey dots: any method."))
    n_levels = max(len(p["levels"]) for p in profile)
    levels = []
    for fam in order:
        p = next(p for p in profile if p["family"] == fam)
        levels.append({"family": fam, "unit": p["unit"],
                       **{f"L{k}": range_text(lo, hi, p["unit"]) for k, (lo, hi) in enumerate(p["bounds"], start=1)}})
    ks = [f"L{k}" for k in range(1, n_levels + 1)]
    s.html.append("<p>Budget levels (nested, mild to extreme):</p>")
    s.html.append(table(levels, [("family", "family", None), ("unit", "unit", None), *[(k, k, esc) for k in ks]],
                        left=("family", "unit", *ks)))
    cols = [("rank", "rank", None), ("family", "family", None), ("method", "method", None), ("n", "images", None),
            *[(k, f"survival % {k}", None) for k in ks],
            *[(f"below_{t:g}", f"survival < {t:g} % at", esc) for t in mx.RANK_THRESHOLDS]]
    s.html.append(table(family_lines(profile, order), cols,
                        left=("family", "method", *[f"below_{t:g}" for t in mx.RANK_THRESHOLDS])))
    return s


def section_convergence(ctx: Context) -> Section | None:
    from ..search import direct_family

    conv = mx.convergence([r for r in ctx.main if r.method in direct_family()])
    if not conv:
        return None
    s = Section("GeoRobust convergence: |PO_k| and RA(k)")
    s.html.append(ctx.figure(F.convergence(conv, title="GeoRobust convergence"), "convergence",
                             "|PO_k|: potentially optimal boxes selected at iteration k. RA(k): their total volume "
                             "as % of the box, when selected (it need not decrease monotonically)."))
    k10 = next((c for c in conv if c["iteration"] == 10), None)
    if k10:
        s.html.append(f"<p>At k = 10: RA mean {fmt_num(k10['ra_mean'])} % (median {fmt_num(k10['ra_median'])} %), "
                      f"|PO| mean {fmt_num(k10['po_mean'])}.</p>")
    cols = [("iteration", "k", None), ("n", "images", None), ("po_mean", "|PO_k| mean", None), ("po_std", "std", None),
            ("po_median", "median", None), ("po_after_mean", "after budget filter", None), ("ra_mean", "RA(k) % mean", None),
            ("ra_std", "std", None), ("ra_q25", "25th", None), ("ra_median", "median", None), ("ra_q75", "75th", None),
            ("nfev_mean", "evals (mean)", None), ("best_median", "median best L (m)", None)]
    s.html.append(table(conv, cols))
    return s


def section_pnp(ctx: Context) -> Section | None:
    rows = ctx.store.jobs(kind="pnp", with_trace=False)
    summary = mx.pnp_summary(rows)
    if not summary:
        return None
    s = Section("PnP solvers")
    s.html.append(ctx.figure(F.pnp_comparison(summary), "pnp_solvers",
                             "Median and mean absolute relative error of the camera position per solver, on the "
                             "ground-truth corners and on the detector's corners (unperturbed images)."))
    s.html.append(table(summary, [("source", "keypoints", None), ("solver", "solver", None), ("n", "images", None),
                                  ("failures", "failures", None), ("median_abs_m", "median (m)", None),
                                  ("mae_abs_m", "MAE (m)", None), ("median_rel_pct", "median (%)", None),
                                  ("mae_rel_pct", "MAE (%)", None), ("p95_rel_pct", "95th pct (%)", None)],
                        left=("source", "solver")))
    cos = [r.payload.get("grad_cosine_bpnp_vs_exact") for r in rows if r.payload]
    cos = [c for c in cos if c is not None]
    if cos:
        s.html.append(f"<p>Gradient agreement of the differentiable layer's BPnP mode with the exact implicit "
                      f"gradient (cosine over the 8 keypoint coordinates, {len(cos)} images): median "
                      f"{np.median(cos):.4f}, 5th percentile {np.percentile(cos, 5):.4f}.</p>")
    return s


def _evaluated(r: JobRow) -> bool:
    return r.status is JobStatus.DONE and r.points is not None and len(r.points) > 0


def _landscape_grids(ctx: Context) -> list[JobRow]:
    """The evaluated landscape grids (landscape role, else the reference grid worth drawing), at most two."""
    grids = ctx.store.jobs(kind="search", role="landscape", with_points=True, with_trace=False)
    if not grids:
        refs = [r for r in ctx.store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
                if _evaluated(r)]
        grids = [_interesting(refs, ctx.eps)] if refs else []
    return [g for g in grids if _evaluated(g)][:2]


def _landscape_runs(ctx: Context, g: JobRow) -> dict[str, JobRow]:
    """Per method (plotting order) the main run drawn over the landscape grid ``g``: on the grid's image, on the
    grid's box, else on the largest box inside it; an evaluation budget before a time budget (a time budget can
    mean thousands of points), then the most evaluations."""
    names = list(g.box.box.names)
    same = [r for r in ctx.runs if r.sample_id == g.sample_id and _evaluated(r) and list(r.box.box.names) == names]
    on_box = [r for r in same if r.box.box.bounds() == g.box.box.bounds()]
    if not on_box and same:
        top = max(r.box_level for r in same)
        on_box = [r for r in same if r.box_level == top]
    first: dict[str, JobRow] = {}
    for r in sorted(on_box, key=lambda r: (r.budget.max_seconds is not None, -r.nfev)):
        first.setdefault(r.method, r)
    return {m: first[m] for m in F.method_order(first)}


def _where(ctx: Context, sid: str) -> str:
    dist = ctx.samples.get(sid, {}).get("slant_distance_m")
    return f"image {sid}" + (f" (slant distance {dist:.0f} m)" if dist else "")


def section_landscapes(ctx: Context) -> Section | None:
    grids = _landscape_grids(ctx)
    if not grids:
        return None
    s = Section("Loss landscape of one image")
    for g in grids:
        names = list(g.box.box.names)
        by_method = _landscape_runs(ctx, g)
        where = _where(ctx, g.sample_id)
        xs, fs = g.points.xs, g.points.fs
        if len(names) == 2:
            fig = F.landscape_2d(xs, fs, names, {m: r.points.xs for m, r in by_method.items()}, eps_safe_m=ctx.eps,
                                 worst={m: r.points.xs[int(np.nanargmax(r.points.fs))] for m, r in by_method.items()},
                                 title=f"L over {g.box_label}, {where}")
            name = "landscape_2d"
        else:
            fig = F.landscape_1d(xs, fs, names[0], {m: (r.points.xs, r.points.fs) for m, r in by_method.items()},
                                 eps_safe_m=ctx.eps, title=f"L over {g.box_label}, {where}")
            name = "landscape_1d"
        lab = ", ".join(f"{F.style(m)['label']} on {r.box_label} ({r.budget_label})" for m, r in by_method.items())
        part = "" if mx.grid_complete(g) else (f", evaluated from the centre outwards and stopped at its first "
                                               f"breach after {len(fs)} of {g.budget.max_evals} points")
        s.html.append(ctx.figure(fig, name, f"Dense grid of {len(fs)} points ({esc(g.box_label)}{part}); "
                                            "markers: "
                                            f"the points each method evaluated — {esc(lab)}; stars: each method's worst "
                                            "point. Red: the ε_safe level set."))
        lines = [{"method": F.style(m)["label"], "box": r.box_label, "budget": r.budget_label, "nfev": r.nfev,
                  "worst": r.worst_m, "x": _theta(r.worst_x), "verdict": r.verdict} for m, r in by_method.items()]
        lines.append({"method": "dense grid", "box": g.box_label, "budget": g.budget_label, "nfev": g.nfev,
                      "worst": g.worst_m, "x": _theta(g.worst_x), "verdict": g.verdict})
        s.html.append(table(lines, [("method", "method", None), ("box", "box", None), ("budget", "budget", None),
                                    ("nfev", "evals", None), ("worst", "worst (m)", None), ("x", "worst θ", esc),
                                    ("verdict", "verdict", None)], left=("method", "box", "budget", "x", "verdict")))
    return s


#: At most this many stored points are replayed for the zones section (whole images, the landscape image first):
#: replay evaluates nothing but re-runs each method's own selection and classifies every cell, about 0.2–0.6 ms
#: per point (so at most about a minute); the rest of a very large run is left to ``vbl-robust zones RUN``.
ZONES_REPLAY_POINTS = 100_000


def _covers(method: str) -> bool:
    cls = METHODS.get(method)
    return cls is not None and cls.covers


def basis_label(zm: ZoneMap) -> str:
    """What a zone map's "ruled out" rests on, in a few words: "sound under L = …" or "estimate — not sound"."""
    if zm.basis == "sound":
        lip = zm.lipschitz
        what = (f"{lip:g} ({zm.norm}-norm of real units)" if not isinstance(lip, tuple)
                else f"({', '.join(f'{v:g}' for v in lip)}) per parameter")
        return f"sound under L = {what}"
    if zm.basis == "estimate":
        return f"estimate — not sound (K̂ = {zm.estimate:.4g}, unit cube)"
    return "no constant — nothing ruled out"


@dataclass(frozen=True)
class Zoned:
    """One main job of a covering method and its zones (None when skipped; ``reason`` says why)."""

    row: JobRow
    zones: JobZones | None
    reason: str = ""

    @property
    def map(self) -> ZoneMap | None:
        return None if self.zones is None else self.zones.zones


def _zones_of(row: JobRow, spec: CampaignSpec) -> Zoned:
    """:func:`~vbl_robust.campaigns.replay.job_zones` on the run's basis: its Lipschitz constant (sound) when it has one, else
    the method's own slope estimate (a map whose cells carry none, a single evaluated cell, keeps no ruled-out
    zone). A replay that fails skips the job, with the reason, and never the report."""
    try:
        try:
            jz = job_zones(row, spec, estimate=spec.lipschitz is None)  # else sound under the run's constant
        except ReplayError:
            raise
        except ValueError:  # cells without a slope estimate (one evaluated cell): classified without a constant
            if spec.lipschitz is not None:
                raise
            jz = job_zones(row, spec)
    except ReplayError as e:
        return Zoned(row, None, f"replay failed: {e}")
    except Exception as e:  # a store this code cannot read must not cost the report
        logger.warning("zones of job %s failed", row.key, exc_info=True)
        return Zoned(row, None, f"{type(e).__name__}: {e}")
    return Zoned(row, jz, "" if jz.zones is not None else jz.note)


def zone_jobs(ctx: Context, first: str | None = None) -> tuple[list[Zoned], list[str]]:
    """The zones of every main job of a method that keeps a cover of its box (DIRECT family, grid), in store order
    per image, image ``first`` (the landscape's) first; and the images left out once :data:`ZONES_REPLAY_POINTS`
    stored points have been replayed."""
    rows = [r for r in ctx.runs if _covers(r.method)]
    by_sample: dict[str, list[JobRow]] = {}
    for r in rows:
        by_sample.setdefault(r.sample_id, []).append(r)
    out: list[Zoned] = []
    left_out: list[str] = []
    spent = 0
    for sid in sorted(by_sample, key=lambda sid: (sid != first, by_sample[sid][0].sample_index)):
        if out and spent >= ZONES_REPLAY_POINTS:
            left_out.append(sid)
            continue
        for r in by_sample[sid]:
            out.append(_zones_of(r, ctx.spec))
            spent += 0 if r.points is None else len(r.points)
    return out, left_out


def zone_lines(jobs: Sequence[Zoned]) -> list[dict[str, Any]]:
    """The zones table: per method (plotting order), box (by level) and budget, the number of jobs with zones, the
    mean and median % of Θ breached / undecided / ruled out over them, the jobs skipped and the bases."""
    groups: dict[tuple[str, str | None, str | None], list[Zoned]] = {}
    for j in jobs:
        groups.setdefault((j.row.method, j.row.box_label, j.row.budget_label), []).append(j)
    methods = F.method_order(m for m, _, _ in groups)
    # boxes of one parameter set together (a family), by level within it
    params = list(dict.fromkeys(js[0].row.box.box.names for js in groups.values()))
    order = {k: (methods.index(k[0]), params.index(js[0].row.box.box.names), js[0].row.box_level or 0.0)
             for k, js in groups.items()}
    lines = []
    for key in sorted(groups, key=order.__getitem__):
        js = groups[key]
        maps = [j.map for j in js if j.map is not None]
        line: dict[str, Any] = {"method": F.style(key[0])["label"], "box": key[1], "budget": key[2],
                                "n": len(maps), "skipped": len(js) - len(maps),
                                "basis": ", ".join(sorted({zm.basis for zm in maps}))}
        for c in CLASSES:
            v = 100.0 * np.array([zm.fractions[c] for zm in maps])
            line[f"{c}_mean"] = float(v.mean()) if len(v) else None
            line[f"{c}_median"] = float(np.median(v)) if len(v) else None
        lines.append(line)
    return lines


_ZONE_COLS = [(f"{c}_{stat}", f"{c.replace('_', ' ')} % {stat}", None) for c in CLASSES for stat in ("mean", "median")]


def section_zones(ctx: Context) -> Section | None:
    """Vulnerability zones: the landscape image's zones drawn over its landscape, and the class fractions of Θ
    over every main job of a method that keeps a cover (DIRECT family, grid). Drawn from what the store holds,
    whatever figures the spec declares; no section without such jobs."""
    if not any(_covers(r.method) for r in ctx.runs):
        return None
    grids = _landscape_grids(ctx)
    g = grids[0] if grids else None
    jobs, left_out = zone_jobs(ctx, None if g is None else g.sample_id)
    s = Section("Vulnerability zones")
    lip = ctx.spec.lipschitz
    s.html.append(
        "<p>Each main search that keeps a cover of Θ (the DIRECT family, the grid) is replayed on its stored values "
        "(nothing is evaluated again) and each of its cells classified: <b>breached</b> — the cell's evaluated point "
        f"is above ε_safe = {ctx.eps:g} m (an observed fact); <b>ruled out</b> — the value plus L·r (r: the cell's "
        "size) stays ≤ ε_safe, so no point of the cell can breach if L bounds the slope; <b>undecided</b> — the "
        "rest, and every cell whose value is unknown. Fractions are shares of Θ's volume.</p>")
    if lip is not None:
        what = (f"{lip:g} (2-norm of real units)" if not isinstance(lip, tuple)
                else f"({', '.join(f'{v:g}' for v in lip)}) per parameter")
        s.html.append(f'<p class="note">Basis: <b>sound under L = {esc(what)}</b>, the run\'s Lipschitz constant: '
                      "ruled-out zones hold under the assumption that it bounds the objective's.</p>")
    else:
        s.html.append('<p class="warn">Basis: <b>estimate — not sound</b>. The run has no Lipschitz constant, so '
                      "L is each search's own estimate K̂ (GeoRobust's: the largest slope it observed; the grid's: "
                      "the largest between neighbouring nodes), which under-estimates the true constant: ruled-out "
                      "zones are a guess, not a certificate. Give the audit <code>--lipschitz</code> for sound "
                      "zones.</p>")
    by_key = {j.row.key: j for j in jobs}
    if g is None or g.box.box.dim > 2:
        s.html.append('<p class="note">No 1-D or 2-D landscape grid in this run: the zones are not drawn '
                      "(<code>vbl-robust zones RUN --plot DIR</code> draws each job's).</p>")
    else:
        drawn, not_drawn = [], []
        for m, r in _landscape_runs(ctx, g).items():
            j = by_key.get(r.key)
            if j is None or j.map is None:
                if j is not None:
                    not_drawn.append(f"{F.style(m)['label']} ({j.reason})")
                continue
            zm = j.map
            box = r.box.box
            inside = np.all((g.points.xs >= box.lower) & (g.points.xs <= box.upper), axis=1)
            name = f"zones_{m}"
            label = basis_label(zm)
            png = plot_zones(zm, ctx.out_dir / "figures" / f"{name}.png",
                             landscape=(g.points.xs[inside], g.points.fs[inside]),
                             title=f"{F.style(m)['label']} zones on {r.box_label}, image {r.sample_id} — "
                                   f"{label.split(' (')[0]}")
            outside = len(j.zones.outside_breaches)
            ground = ("the dense grid's L(θ) (line)" if box.dim == 1
                      else "the dense grid's L(θ) (heat map; dashed: ε_safe)")
            s.html.append(ctx.figure_file(png, name, (
                f"{esc(F.style(m)['label'])} on {esc(r.box_label)} (budget {esc(r.budget_label)}; {r.nfev} evaluated), "
                f"{esc(_where(ctx, r.sample_id))}: "
                f"{len(zm.zones)} cells over {ground}. Red: breached; grey: undecided; green: ruled out. Basis: "
                f"<b>{esc(label)}</b>." + (f" {outside} breaching evaluation(s) are no cell's centre (not drawn as "
                                           "zones)." if outside else ""))))
            drawn.append({"method": F.style(m)["label"], "box": r.box_label, "budget": r.budget_label,
                          "nfev": r.nfev, "cells": len(zm.zones),
                          **{c: 100.0 * zm.fractions[c] for c in CLASSES}, "basis": label})
        if not_drawn:
            s.html.append(f'<p class="warn">Not drawn (no zones): {esc("; ".join(not_drawn))}.</p>')
        if drawn:
            s.html.append(table(drawn, [("method", "method", None), ("box", "box", None), ("budget", "budget", None),
                                        ("nfev", "evals", None), ("cells", "cells", None),
                                        *[(c, f"{c.replace('_', ' ')} %", None) for c in CLASSES],
                                        ("basis", "basis", esc)], left=("method", "box", "budget", "basis")))
    done = sorted({j.row.sample_id for j in jobs})
    s.html.append(f"<p>Over all main jobs of covering methods ({len(done)} images"
                  + (f"; the other {len(left_out)} image(s) were not replayed: the report replays at most "
                     f"{ZONES_REPLAY_POINTS} stored evaluations, <code>vbl-robust zones RUN</code> every job"
                     if left_out else "") + "): % of Θ per class, mean and median over jobs.</p>")
    s.html.append(table(zone_lines(jobs), [("method", "method", None), ("box", "box", None),
                                           ("budget", "budget", None), ("n", "jobs", None), *_ZONE_COLS,
                                           ("skipped", "skipped", None), ("basis", "basis", None)],
                        left=("method", "box", "budget", "basis")))
    implied = sum(1 for j in jobs if j.map is None and j.row.status == JobStatus.IMPLIED)
    skipped = [j for j in jobs if j.map is None and j.row.status != JobStatus.IMPLIED]
    if implied:
        s.html.append(f"<p>{implied} job(s) implied by a breach at a smaller box of their chain ran no search: no "
                      "zones.</p>")
    if skipped:
        s.html.append(f'<p class="warn">{len(skipped)} job(s) skipped (no zones)'
                      + (", the first 50:" if len(skipped) > 50 else ":") + "</p>")
        s.html.append(table([{"sample_id": j.row.sample_id, "method": j.row.method, "box": j.row.box_label,
                              "budget": j.row.budget_label, "reason": j.reason} for j in skipped[:50]],
                            [("sample_id", "image", None), ("method", "method", None), ("box", "box", None),
                             ("budget", "budget", None), ("reason", "reason", None)],
                            left=("sample_id", "method", "box", "budget", "reason")))
    return s


def _interesting(grids: Sequence[JobRow], eps: float) -> JobRow:
    """The 1-D reference grid worth drawing: an image that survives unperturbed (L(0) ≤ ε) but breaches somewhere
    in the box, with its breach region smallest; else the surviving image with the largest worst value."""
    def nominal(g: JobRow) -> float:
        i = int(np.argmin(np.abs(g.points.xs[:, 0])))
        return float(g.points.fs[i]) if np.isfinite(g.points.fs[i]) else math.inf

    ok = [g for g in grids if nominal(g) <= eps]
    if not ok:
        return grids[0]
    breach = [g for g in ok if np.nanmax(g.points.fs) > eps]
    if breach:
        return min(breach, key=lambda g: (np.mean(np.where(np.isfinite(g.points.fs), g.points.fs, math.inf) > eps),
                                          g.sample_index))
    return max(ok, key=lambda g: np.nanmax(g.points.fs))


def section_best_vs_evals(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.status is JobStatus.DONE and r.trace]
    if not rows:
        return None
    n_max = max(r.nfev for r in rows)
    grid_n = np.unique(np.linspace(1, max(n_max, 1), 200).astype(int))
    curves = {}
    for m in F.method_order(r.method for r in rows):
        mats = []
        for r in (r for r in rows if r.method == m):
            n = np.array([t.nfev for t in r.trace])
            b = np.array([t.best_value for t in r.trace], dtype=np.float64)
            idx = np.searchsorted(n, grid_n, side="right") - 1
            v = np.where(idx >= 0, b[np.clip(idx, 0, None)], np.nan)
            v[grid_n > n[-1]] = b[-1]  # stopped early (breach): keeps its best
            mats.append(v)
        mat = np.array(mats)
        med = np.full(len(grid_n), np.nan)
        some = np.isfinite(mat).any(axis=0)
        med[some] = np.nanmedian(mat[:, some], axis=0)
        curves[m] = (grid_n, med)
    s = Section("Worst error found vs evaluations")
    s.html.append(ctx.figure(F.best_vs_evals(curves, eps_safe_m=ctx.eps, title="Search progress (median over images)"),
                             "best_vs_evals", "A search that stopped at a breach keeps its final value."))
    return s


def section_per_image(ctx: Context) -> Section | None:
    if not ctx.main:
        return None
    methods = F.method_order(r.method for r in ctx.main)
    by: dict[str, dict[str, Any]] = {}
    for r in ctx.main:
        line = by.setdefault(r.sample_id, {"sample_id": r.sample_id, **_sample_cols(ctx, r.sample_id)})
        line[f"{r.method}_worst"] = r.worst_m
        line[f"{r.method}_verdict"] = r.verdict
        line[f"{r.method}_x"] = _theta(r.worst_x)
    lines = list(by.values())
    for line in lines:
        line["worst"] = max(-math.inf if line.get(f"{m}_worst") is None else line[f"{m}_worst"] for m in methods)
        line["verdict"] = (Verdict.BREACH if line["worst"] > ctx.eps else
                           Verdict.CERTIFIED if any(line.get(f"{m}_verdict") is Verdict.CERTIFIED for m in methods)
                           else Verdict.NO_BREACH_FOUND)
    cols = [("sample_id", "image", None), ("slant_distance_m", "slant dist. (m)", None), ("envelope", "envelope", None)]
    for m in methods:
        cols += [(f"{m}_worst", f"{F.style(m)['label']} worst (m)", None), (f"{m}_x", "at θ", esc)]
    cols += [("worst", "worst of all (m)", None), ("verdict", "verdict", None)]
    s = Section("Per image: worst case found")
    s.html.append(table(lines, cols, row_class=lambda r: "breach" if r["verdict"] is Verdict.BREACH else "",
                        left=("sample_id", "envelope", "verdict", *[f"{m}_x" for m in methods])))
    return s


def _theta(x: Mapping[str, float] | None) -> str:
    """A worst point in short form: "roll_deg=2.22, contrast=1.05"."""
    return ", ".join(f"{k}={v:.3g}" for k, v in (x or {}).items())


def _sample_cols(ctx: Context, sid: str) -> dict[str, Any]:
    s = ctx.samples.get(sid, {})
    return {"slant_distance_m": s.get("slant_distance_m"), "envelope": s.get("envelope")}


def section_provenance(ctx: Context) -> Section:
    s = Section("Provenance")
    runs = ctx.store.runs()
    s.html.append(table(runs, [("run_id", "run", None), ("started_at", "started (UTC)", None),
                               ("finished_at", "finished", None), ("status", "status", None),
                               ("code_version", "code version", None), ("executor", "executor", None),
                               ("host", "host", None), ("jobs_total", "jobs", None), ("jobs_skipped", "already done", None),
                               ("jobs_done", "done in run", None), ("seconds", "seconds", None)],
                        left=("started_at", "finished_at", "status", "code_version", "executor", "host")))
    if runs:
        last = runs[-1]
        det = last.get("detector") or {}
        ds = last.get("dataset") or {}
        s.html.append(f"<p>Detector: {esc(det.get('name'))}; model file SHA-256 <code>{esc(det.get('sha256'))}</code>.<br>"
                      f"Dataset: {esc(json.dumps(ds.get('source')))}; {ds.get('n')} images; identity "
                      f"<code>{esc(ds.get('sha256'))}</code>.</p>")
        s.html.append("<details><summary>Full configuration of the last run (JSON)</summary><pre>"
                      f"{esc(json.dumps(last.get('config'), indent=1))}</pre></details>")
    return s


#: The section drawing each figure a campaign can declare (``CampaignSpec.figures``), in report order.
SECTIONS: dict[str, Callable[[Context], Section | None]] = {
    "pnp": section_pnp, "survival": section_survival_level, "runtime": section_runtime, "distance": section_distance,
    "families": section_families, "convergence": section_convergence, "landscape": section_landscapes, "progress": section_best_vs_evals,
    "per_image": section_per_image,
}


def build_report(run: str | Path, out: str | Path | None = None) -> Path:
    """Write ``report.html`` (self-contained) and ``figures/*.png`` for the run directory (or store file) ``run``;
    returns the HTML path. ``out`` defaults to the run directory."""
    run = Path(run)
    with ResultStore.open_existing(run) as store:
        camp = store.campaign()
        if camp is None:
            raise ValueError(f"{run}: the results store holds no campaign yet")
        spec = CampaignSpec.from_dict(camp["spec"])
        out_dir = Path(out) if out is not None else (run if run.is_dir() else run.parent)
        ctx = Context(store, spec, out_dir, mx.main_rows(store, spec), store.samples())
        exp = EXPERIMENTS.get(spec.name)
        title = exp.title if exp else "Robustness audit"
        sections = [section_overview(ctx, title)]
        declared = spec.report_figures
        for name in FIGURES:
            builds = [SECTIONS[name]] if name in declared else []
            if name == "landscape":  # the zones follow the landscape, declared or not (they need no declaration)
                builds.append(section_zones)
            for build in builds:
                try:
                    sec = build(ctx)
                except Exception:  # one broken section must not hide the others
                    logger.exception("report section %s failed", build.__name__)
                    sec = Section(build.__name__.removeprefix("section_"),
                                  ['<p class="warn">This section failed to build; see the log.</p>'])
                if sec is not None:
                    sections.append(sec)
        sections.append(section_provenance(ctx))
    body = [f"<h1>vbl-robust — {esc(title)} <small>({esc(spec.name)})</small></h1>"]
    for sec in sections:
        body.append(f"<h2>{esc(sec.title)}</h2>")
        body.extend(sec.html)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "report.html"
    path.write_text(page(f"vbl-robust {spec.name}", "\n".join(body)))
    return path
