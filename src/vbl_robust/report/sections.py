"""The report's sections, one function each (``section_*``: a :class:`~vbl_robust.report.rows.Context` in, a
:class:`~vbl_robust.report.rows.Section` or None out), and the tables they share."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..analysis.breach import survival_rate
from ..analysis.levels import RANK_THRESHOLDS, distance_profile, family_of, family_profile, rank_families
from ..analysis.metrics import convergence, pnp_summary
from ..analysis.reference import AgainstGrid, against_reference, grid_complete
from ..analysis.summary import Summary, summarize
from ..consent import DetectorKind
from ..constants import FAILURE_REASONS, Verdict
from ..search.evaluations import NON_FINITE
from ..specs.campaign import range_text
from ..specs.kinds import JobKind, JobStatus, Role
from ..store.rows import JobRow, RunProvenance
from . import figures as F
from .figure_style import method_order, style
from .html import esc, fmt_num, folded, table
from .integrity import provenance_html
from .rows import (
    Context,
    Section,
    anchor,
    landscape_grids,
    landscape_runs,
    main_boxes,
    reference,
    sample_cols,
    theta_text,
    where,
)


def _summary_table(summary: Sequence[Summary], unit: str = "image") -> str:
    """Per method, box and budget: survival with its exact 95 % interval, breaches split by kind (misleading /
    flagged only), verdicts and effort."""
    cols = [
        ("method", "method", None), ("box_label", "box", None), ("budget_label", f"budget per {unit}", None),
        ("n", f"{unit}s", None), ("survival_text", "survival % [95 % CI]", esc),
        ("median_worst_m", "median worst (m)", None), ("breaches", "breaches", None),
        ("misleading", "misleading", None), ("flagged", "flagged only", None), ("certified", "certified", None),
        ("mean_nfev", "mean evals", None), ("failed_evals", "failed evals", None),
        ("median_search_s", "median s", None),
    ]
    if any(line.n_empty for line in summary):  # survivors that were never searched: say how many
        cols.insert(5, ("n_empty", "no evaluation in time", None))
    if any(line.not_measured for line in summary):  # jobs the tool could not complete: in no rate
        cols.insert(4, ("not_measured", "not measured", None))
    if any(line.read_from for line in summary):
        cols.append(("read_from", "read off the run", None))
    rows = [{**ln.as_row(), "survival_text": ln.survival_rate.text(1, percent=False) if ln.measured else "–"}
            for ln in summary]
    return table(rows, cols, left=("method", "box_label", "budget_label", "read_from"))


def _failures_table(summary: Sequence[Summary], penalty_m: float) -> str:
    """Failed evaluations per reason and group (the search used the penalty for them), with the codes' meaning."""
    codes = sorted({c for line in summary for c in line.failures})
    if not codes:
        return ""
    lines = [{**line.as_row(), **{f"reason:{c}": line.failures.get(c, 0) for c in codes}} for line in summary]
    cols = [("method", "method", None), ("box_label", "box", None), ("budget_label", "budget per image", None),
            ("nfev", "evaluations", None), ("failed_evals", "failed", None),
            *[(f"reason:{c}", c, None) for c in codes]]
    meaning = {**FAILURE_REASONS, NON_FINITE: "the objective returned NaN or ±inf"}
    legend = "; ".join(f"<code>{esc(c)}</code>: {esc(meaning.get(c, c))}" for c in codes)
    return (f"<p>Failed evaluations by reason (each counts in the search with the {penalty_m:g} m penalty): "
            f"{legend}.</p>" + table(lines, cols, left=("method", "box_label", "budget_label")))


def detector_facts(det: dict) -> str:
    """Which pipeline was audited, from a stored detector identity: design (single pass / two-stage), input size,
    engine and the model's short SHA-256 (each where known)."""
    parts = [det.get("design") or "",
             f"input {det['input_size']} px" if det.get("input_size") else "",
             f"engine {det['engine']}" if det.get("engine") else "",
             f"sha256 {str(det['sha256'])[:12]}" if det.get("sha256") else ""]
    return ", ".join(p for p in parts if p) or "–"


# -- sections ------------------------------------------------------------------------------------------------
def section_overview(ctx: Context, title: str) -> Section:
    s = Section("Summary")
    runs = ctx.store.runs()
    last = runs[-1].provenance if runs else RunProvenance()
    det = last.detector or {}
    n_done = ctx.store.count()
    total = last.jobs_total
    s.html.append(
        f"<p><b>{esc(title)}</b>. Detector: <b>{esc(det.get('name', '?'))}</b> ({esc(detector_facts(det))}); "
        f"{len(ctx.samples)} {ctx.spec.unit}s; "
        f"ε_safe = {ctx.eps:g} m, τ_conf = {ctx.spec.settings.conf_threshold:g}, failure penalty {ctx.spec.settings.penalty_m:g} m, "
        f"PnP solver <code>{esc(ctx.spec.settings.pnp)}</code>, seed {ctx.spec.seed}. Jobs in the store: {n_done}"
        + (f" of {total}" if total else "") + ".</p>")
    if ctx.spec.notes:
        s.html.append(f'<p class="note">{esc(ctx.spec.notes)}</p>')
    for goal in det.get("open_goals") or []:
        s.html.append(f'<p class="warn">Open accuracy goal of this detector (its model card): {esc(goal)}.</p>')
    if det.get("kind") == DetectorKind.ORACLE:
        s.html.append('<p class="warn">The oracle detector returns the exact projected runway corners: these results '
                      "describe a perfect detector (roll about the optical axis does not move the camera), not a "
                      "trained model.</p>")
    if total and n_done < total:
        s.html.append(f'<p class="warn">The campaign is incomplete ({n_done} of {total} jobs): rerun the same '
                      "command to resume.</p>")
    if ctx.unmeasured:
        s.html.append(f'<p class="warn">{len(ctx.unmeasured)} job(s) could not be measured by the tool; they are in '
                      "no rate (not as breaches, not as survivors):</p>")
        lines = [{"sample_id": r.sample_id, "method": r.method, "box_label": r.box_label,
                  "kind": r.not_measured.value, "reason": r.not_measured_detail} for r in ctx.unmeasured[:50]]
        s.html.append(table(lines, [("sample_id", "sample", None), ("method", "method", None),
                                    ("box_label", "box", None), ("kind", "why", None), ("reason", "reason", None)],
                            left=("sample_id", "method", "box_label", "kind", "reason"),
                            fold="The jobs not measured" + (f" (the first 50 of {len(ctx.unmeasured)})"
                                                            if len(ctx.unmeasured) > 50 else "")))
    return s


#: The title of :func:`section_methods`, whose table the figures' sections link to when they would repeat it.
METHODS_TITLE = "Per method, box and budget"


def section_methods(ctx: Context) -> Section | None:
    """Per method, box and budget: the summary table and, folded, the failed evaluations by reason."""
    if not ctx.main:
        return None
    s = Section(METHODS_TITLE)
    summary = summarize([*ctx.main, *(r for r in ctx.unmeasured if r.kind == JobKind.SEARCH and r.role == Role.MAIN)],
                        ctx.eps)
    s.html.append(_summary_table(summary, ctx.spec.unit))
    failures = _failures_table(summary, ctx.spec.settings.penalty_m)
    if failures:
        s.html.append(folded("Failed evaluations by reason", failures))
    return s


def _repeats_methods_table(ctx: Context, rows: Sequence[JobRow], by: tuple[str, str]) -> bool:
    """True when summarising ``rows`` by ``by`` gives the rows of :func:`section_methods`' table again: they are
    all the main rows and the grouping drops only a key that has one value per group (one budget per method and
    box, or one box)."""
    if len(rows) != len(ctx.main):
        return False
    dropped = "budget_label" if "budget_label" not in by else "box_label"
    values: dict[tuple, set] = {}
    for r in rows:
        values.setdefault(tuple(getattr(r, k) for k in by), set()).add(getattr(r, dropped))
    return all(len(v) == 1 for v in values.values())


def _methods_link(unit: str) -> str:
    return (f'<p class="note">The numbers behind this figure — per method and box: {unit}s, survival with its exact '
            f'95 % interval, breaches by kind, effort — are the table in <a href="#{anchor(METHODS_TITLE)}">'
            f"{esc(METHODS_TITLE)}</a> above (not repeated here).</p>")


def section_survival_level(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.chain is None]
    if len({r.box_level for r in rows}) < 2:
        return None
    boxes = main_boxes(ctx)
    summary = summarize(rows, ctx.eps, by=("method", "box_label"))
    ref = summarize(reference(ctx, boxes), ctx.eps, by=("method", "box_label"))
    two_d = any(b.box.dim > 1 for b in boxes)
    ticks = {b.level: b.label for b in boxes} if two_d else None
    title = "Survival vs roll and contrast budget" if two_d else "Survival vs roll budget"
    s = Section(title)
    fig = F.survival_vs_level(summary + ref, title=title, tick_labels=ticks,
                              xlabel="perturbation box (roll half-width, contrast range)" if two_d else "roll budget")
    s.html.append(ctx.figure(fig, "survival_2d" if two_d else "survival_1d",
                             "Survival rate S_rate: share of images whose worst error found stays ≤ ε_safe. Lower "
                             "means the search found more breaches (a stronger search)."))
    if _repeats_methods_table(ctx, rows, ("method", "box_label")):
        s.html.append(_methods_link(ctx.spec.unit))
        if ref:
            s.html.append("<p>The dense grid (the true worst case up to its spacing):</p>" + _summary_table(ref))
    else:
        s.html.append(_summary_table(summary + ref))
    s.html.append(_against_grid_table(against_reference(rows, reference(ctx, boxes), ctx.eps), ctx.spec.unit))
    return s


def _against_grid_table(lines: Sequence[AgainstGrid], unit: str = "image") -> str:
    """Each method's verdicts against the dense grid's on the same images (:func:`~vbl_robust.analysis.reference.
    against_reference`); "" without a grid."""
    if not lines:
        return ""
    cols = [("method", "method", None), ("box_label", "box", None), ("budget_label", f"budget per {unit}", None),
            ("n", f"{unit}s", None), ("grid_breaches", "grid breaches", None), ("found", "found", None),
            ("missed", "missed", None), ("beyond_grid", "beyond the grid", None), ("found_pct", "found %", None),
            ("p_value", "McNemar p", lambda v: f"{v:.2g}")]
    return (f"<p>Is the worst case really found? Each method against the dense grid on the same {unit}s: of the "
            f"{unit}s the grid breaks, how many the method breaks too (found) or not (missed); beyond the grid: "
            f"{unit}s the method breaks and the grid does not (a breach between its nodes); exact McNemar p of "
            "method vs grid (small: the difference is not chance).</p>"
            + table([dataclasses.asdict(ln) for ln in lines], cols, left=("method", "box_label", "budget_label")))


def section_runtime(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if r.budget is not None]
    time_rows = [r for r in rows if r.budget.max_seconds is not None]
    eval_rows = [r for r in rows if r.budget.max_seconds is None and r.budget.max_evals is not None]
    if len({r.budget_label for r in time_rows}) < 2 and len({r.budget_label for r in eval_rows}) < 2:
        return None
    boxes = main_boxes(ctx)
    ref_rows = reference(ctx, boxes)
    ref = None
    if ref_rows:
        w = [r.worst_m for r in ref_rows]
        ref = {"survival": survival_rate(w, ctx.eps), "median_worst_m": float(np.median(w))}
    box_label = boxes[0].label if boxes else ""
    s = Section(f"Runtime budgets ({box_label})")
    same = _repeats_methods_table(ctx, [*time_rows, *eval_rows], ("method", "budget_label"))
    for axis, rs, name in (("max_seconds", time_rows, "time"), ("max_evals", eval_rows, "evals")):
        if len({r.budget_label for r in rs}) < 2:
            continue
        summary = [dataclasses.replace(line, box_label=box_label)
                   for line in summarize(rs, ctx.eps, by=("method", "budget_label"))]
        dims = "2d" if boxes and boxes[0].box.dim > 1 else "1d"
        fig = F.runtime(summary, axis=axis, eps_safe_m=ctx.eps, reference=ref,
                        title=f"{'Time' if axis == 'max_seconds' else 'Evaluation'} budget per image, box {box_label}")
        s.html.append(ctx.figure(fig, f"runtime_{dims}_{name}",
                                 "Left: survival rate; right: median over images of the worst error found "
                                 "(no early stop). Dashed black: the dense grid's true worst case."))
        if not same:
            s.html.append(_summary_table(summary, ctx.spec.unit))
    if same:
        s.html.append(_methods_link(ctx.spec.unit))
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
    distances = {sid: s.slant_distance_m for sid, s in ctx.samples.items()}
    budgets = sorted({r.box_level for r in rows})
    limit = max(budgets)
    ref = reference(ctx, main_boxes(ctx))
    profile = distance_profile(rows + ref, distances, budgets)
    s = Section("Vulnerability profile by approach distance")
    fig = F.distance_profile(profile, limit_deg=limit, budgets=budgets)
    s.html.append(ctx.figure(fig, "distance_profile",
                             "φ_crit per slant-distance quartile: the smallest roll budget at which the quartile's "
                             f"survival drops below 10 %. Bars in the red band: survival never dropped below 10 % "
                             f"within ±{limit:g}°."))
    lines = [{**dataclasses.asdict(p), "survival_str": " / ".join(fmt_num(v) for v in p.survival),
              "phi": f"≥ {limit:g}°" if not math.isfinite(p.phi_crit) else f"{p.phi_crit:g}°",
              "range": f"{p.d_min_m:.0f}–{p.d_max_m:.0f}"} for p in profile]
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
        for m in method_order(series):
            p = series[m]
            line: dict[str, Any] = {"rank": rank, "family": fam, "method": style(m)["label"],
                                    "n": max(p["n"], default=0)}
            line.update({f"L{k}": v for k, v in enumerate(p["survival"], start=1)})
            for t in RANK_THRESHOLDS:
                line[f"below_{t:g}"] = _level_name(p, p[f"below_{t:g}"])
            lines.append(line)
    return lines


def section_families(ctx: Context) -> Section | None:
    rows = [r for r in ctx.main if family_of(r) is not None]
    if not rows:
        return None
    ref = reference(ctx, main_boxes(ctx))
    profile = family_profile(rows + ref, ctx.eps)
    order = rank_families(profile)
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
            *[(f"below_{t:g}", f"survival < {t:g} % at", esc) for t in RANK_THRESHOLDS]]
    s.html.append(table(family_lines(profile, order), cols,
                        left=("family", "method", *[f"below_{t:g}" for t in RANK_THRESHOLDS])))
    return s


def section_convergence(ctx: Context) -> Section | None:
    from ..search.api import direct_family

    conv = convergence([r for r in ctx.main if r.method in direct_family()])
    if not conv:
        return None
    s = Section("GeoRobust convergence: |PO_k| and RA(k)")
    s.html.append(ctx.figure(F.convergence(conv, title="GeoRobust convergence"), "convergence",
                             "|PO_k|: potentially optimal boxes selected at iteration k. RA(k): their total volume "
                             "as % of the box, when selected (it need not decrease monotonically)."))
    k10 = next((c for c in conv if c.iteration == 10), None)
    if k10:
        s.html.append(f"<p>At k = 10: RA mean {fmt_num(k10.ra_mean)} % (median {fmt_num(k10.ra_median)} %), "
                      f"|PO| mean {fmt_num(k10.po_mean)}.</p>")
    cols = [("iteration", "k", None), ("n", "images", None), ("po_mean", "|PO_k| mean", None), ("po_std", "std", None),
            ("po_median", "median", None), ("po_after_mean", "after budget filter", None), ("ra_mean", "RA(k) % mean", None),
            ("ra_std", "std", None), ("ra_q25", "25th", None), ("ra_median", "median", None), ("ra_q75", "75th", None),
            ("nfev_mean", "evals (mean)", None), ("best_median", "median best L (m)", None)]
    s.html.append(table([dataclasses.asdict(c) for c in conv], cols))
    return s


def section_pnp(ctx: Context) -> Section | None:
    rows = ctx.store.jobs(kind="pnp", with_trace=False)
    summary = pnp_summary(rows)
    if not summary:
        return None
    s = Section("PnP solvers")
    s.html.append(ctx.figure(F.pnp_comparison(summary), "pnp_solvers",
                             "Median and mean absolute relative error of the camera position per solver, on the "
                             "ground-truth corners and on the detector's corners (unperturbed images)."))
    s.html.append(table([dataclasses.asdict(p) for p in summary], [("source", "keypoints", None), ("solver", "solver", None), ("n", "images", None),
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


def section_landscapes(ctx: Context) -> Section | None:
    grids = landscape_grids(ctx)
    if not grids:
        return None
    s = Section("Loss landscape of one image")
    for g in grids:
        names = list(g.box.box.names)
        by_method = landscape_runs(ctx, g)
        place = where(ctx, g.sample_id)
        xs, fs = g.points.xs, g.points.fs
        # a grid stopped at its first breach covers the centre of the box only: the title says so, the axes span
        # the whole box it names
        stopped = "" if grid_complete(g) else (f"; the grid stopped at its first breach after {len(fs)} of "
                                               f"{g.budget.max_evals} points (blank: not evaluated)")
        title = f"L over {g.box_label}, {place}{stopped}"
        if len(names) == 2:
            fig = F.landscape_2d(xs, fs, names, {m: r.points.xs for m, r in by_method.items()}, eps_safe_m=ctx.eps,
                                 worst={m: r.points.xs[int(np.nanargmax(r.points.fs))] for m, r in by_method.items()},
                                 title=title, bounds=list(zip(g.box.box.lower, g.box.box.upper, strict=True)))
            name = "landscape_2d"
        else:
            fig = F.landscape_1d(xs, fs, names[0], {m: (r.points.xs, r.points.fs) for m, r in by_method.items()},
                                 eps_safe_m=ctx.eps, title=title)
            name = "landscape_1d"
        lab = ", ".join(f"{style(m)['label']} on {r.box_label} ({r.budget_label})" for m, r in by_method.items())
        part = "" if not stopped else (f", evaluated from the centre outwards and stopped at its first "
                                       f"breach after {len(fs)} of {g.budget.max_evals} points")
        s.html.append(ctx.figure(fig, name, f"Dense grid of {len(fs)} points ({esc(g.box_label)}{part}); "
                                            "markers: "
                                            f"the points each method evaluated — {esc(lab)}; stars: each method's worst "
                                            "point. Red: the ε_safe level set."))
        lines = [{"method": style(m)["label"], "box": r.box_label, "budget": r.budget_label, "nfev": r.nfev,
                  "worst": r.worst_m, "x": theta_text(r.worst_x), "verdict": r.verdict} for m, r in by_method.items()]
        lines.append({"method": "dense grid", "box": g.box_label, "budget": g.budget_label, "nfev": g.nfev,
                      "worst": g.worst_m, "x": theta_text(g.worst_x), "verdict": g.verdict})
        s.html.append(table(lines, [("method", "method", None), ("box", "box", None), ("budget", "budget", None),
                                    ("nfev", "evals", None), ("worst", "worst (m)", None), ("x", "worst θ", esc),
                                    ("verdict", "verdict", None)], left=("method", "box", "budget", "x", "verdict")))
    return s


def progress_curves(rows: Sequence[JobRow], points: int = 200) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method, the median over its rows of the worst error found so far, at up to ``points`` evaluation
    counts: ``{method: (counts, medians)}``. Each row's value is carried forward past its last trace point (a
    search stopped at a breach keeps its final value), and a curve starts at the first count where every row has
    a point: every row counts at every count, so a median never falls (a median over the rows that happen to have
    a point at a count did: the late starters joined low)."""
    curves = {}
    for m in method_order(r.method for r in rows):
        traces = [(np.array([t.nfev for t in r.trace]),  # no value yet (NaN): nothing found so far
                   np.nan_to_num(np.array([t.best_value for t in r.trace], dtype=np.float64), nan=-np.inf))
                  for r in rows if r.method == m]
        start = max(int(n[0]) for n, _ in traces)
        end = max(int(n[-1]) for n, _ in traces)
        grid_n = np.unique(np.linspace(start, max(end, start), points).astype(int))
        mat = np.array([b[np.searchsorted(n, grid_n, side="right") - 1] for n, b in traces])
        curves[m] = (grid_n, np.median(np.maximum.accumulate(mat, axis=1), axis=0))
    return curves


def section_best_vs_evals(ctx: Context) -> Section | None:
    """The worst error found against evaluations (:func:`progress_curves`): one search per image and method — on
    the largest box, at the largest budget — so that the median is over images."""
    rows = [r for r in ctx.main if r.status == JobStatus.DONE and r.trace]
    if not rows:
        return None
    top = max(r.box_level or 0.0 for r in rows)
    one: dict[tuple[str, str], JobRow] = {}
    for r in sorted((r for r in rows if (r.box_level or 0.0) == top), key=lambda r: r.nfev):
        one[(r.method, r.sample_id)] = r  # the longest search of each image and method
    rows = list(one.values())
    n = len({r.sample_id for r in rows})
    s = Section("Worst error found vs evaluations")
    s.html.append(ctx.figure(F.best_vs_evals(progress_curves(rows), eps_safe_m=ctx.eps,
                                             title=f"Search progress on {rows[0].box_label} (median over {n} "
                                                   f"{ctx.spec.unit}s)"),
                             "best_vs_evals", f"Per method, the median over the {ctx.spec.unit}s of the worst error "
                             "found so far; each search counts at every evaluation count (one that stopped at a "
                             "breach keeps its final value), from the first count where every search has a point."))
    return s


def section_per_image(ctx: Context) -> Section | None:
    if not ctx.main:
        return None
    methods = method_order(r.method for r in ctx.main)
    by: dict[str, dict[str, Any]] = {}
    for r in ctx.main:
        line = by.setdefault(r.sample_id, {"sample_id": r.sample_id, **sample_cols(ctx, r.sample_id),
                                           "nominal_m": getattr(ctx.nominal.get(r.sample_id), "error_m", None)})
        line[f"{r.method}_worst"] = r.worst_m
        line[f"{r.method}_verdict"] = r.verdict
        line[f"{r.method}_x"] = theta_text(r.worst_x)
    lines = list(by.values())
    for line in lines:
        line["worst"] = max(-math.inf if line.get(f"{m}_worst") is None else line[f"{m}_worst"] for m in methods)
        line["verdict"] = (Verdict.BREACH if line["worst"] > ctx.eps else
                           Verdict.CERTIFIED if any(line.get(f"{m}_verdict") == Verdict.CERTIFIED for m in methods)
                           else Verdict.NO_BREACH_FOUND)
    cols = [("sample_id", ctx.spec.unit, None), ("slant_distance_m", "slant dist. (m)", None),
            ("envelope", "envelope", None), ("nominal_m", "unperturbed L(0) (m)", None)]
    for m in methods:
        cols += [(f"{m}_worst", f"{style(m)['label']} worst (m)", None), (f"{m}_x", "at θ", esc)]
    cols += [("worst", "worst of all (m)", None), ("verdict", "verdict", None)]
    s = Section(f"Per {ctx.spec.unit}: worst case found")
    s.html.append(f"<p>L(0): the error of the {ctx.spec.unit} unperturbed (θ at its identity: roll 0, contrast 1, …; "
                  f"the {ctx.spec.settings.penalty_m:g} m penalty where the pipeline gives no pose; – in a run stored before "
                  "it was). An L(0) near ε_safe means the perturbation had little to break.</p>")
    s.html.append(table(lines, cols, row_class=lambda r: "breach" if r["verdict"] == Verdict.BREACH else "",
                        left=("sample_id", "envelope", "verdict", *[f"{m}_x" for m in methods]),
                        fold=f"Each {ctx.spec.unit}'s worst case per method (breaches in red)"))
    return s


def section_provenance(ctx: Context) -> Section:
    s = Section("Provenance")
    runs = ctx.store.runs()
    s.html.append(table([r.to_dict() for r in runs], [("run_id", "run", None), ("started_at", "started (UTC)", None),
                               ("finished_at", "finished", None), ("status", "status", None),
                               ("code_version", "code version", None), ("executor", "executor", None),
                               ("host", "host", None), ("jobs_total", "jobs", None), ("jobs_skipped", "already done", None),
                               ("jobs_done", "done in run", None), ("seconds", "seconds", None)],
                        left=("started_at", "finished_at", "status", "code_version", "executor", "host")))
    if runs:
        last = runs[-1].provenance
        det = last.detector or {}
        ds = last.dataset or {}
        s.html.append(f"<p>Detector: {esc(det.get('name'))}; model file SHA-256 <code>{esc(det.get('sha256'))}</code>.<br>"
                      f"Dataset: {esc(json.dumps(ds.get('source')))}; {ds.get('n')} images; identity "
                      f"<code>{esc(ds.get('sha256'))}</code>.</p>")
        s.html.append("<details><summary>Full configuration of the last run (JSON)</summary><pre>"
                      f"{esc(json.dumps(last.config, indent=1))}</pre></details>")
    s.html.append(provenance_html(ctx))  # the store's head digest (vbl-robust verify RUN --head …)
    return s
