"""The evidence a run gives, organised as a safety case reads it: what was covered, how sure the numbers are, how
complete the search was, and the worst cases found. Worded as evidence, not as a compliance claim.

:func:`evidence_of` computes it from a report :class:`~vbl_robust.report.rows.Context` (nothing is evaluated);
:func:`section_evidence` renders it as the report's first screen ("safe where, and how sure"), :mod:`.gallery`
draws its worst cases, and ``evidence.json`` beside ``report.html`` holds the same numbers
(:meth:`Evidence.to_dict`).

Per box, the images are counted over **every method together** (an image is breached when any method found a
breach): survival, misleading and flagged-only images each with their exact 95 % interval
(:class:`vbl_robust.stats.Rate`); for random search, the largest bound over its surviving images on the breached
fraction of the box (:func:`vbl_robust.analysis.breach.residual_bound`); for a risk run, each estimator's pooled
failure probability with its interval (:func:`vbl_robust.risk.pooled_risk`); for the DIRECT family, the
mean remaining area RA of the last iteration (the share of Θ not yet pruned as below the best value found).

The worst cases (:func:`worst_cases`): one per breached image, at its most severe breach — misleading before
unknown before flagged only (a confident pose far off is the hazard the system cannot see; a flagged failure it
can), then the larger error, then the smaller box — at most :data:`WORST_CASES`, ordered the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..analysis import breach as br
from ..atomic import atomic_write
from ..constants import BreachKind, Verdict
from ..search.api import direct_family
from ..specs.kinds import SourceKind
from ..stats import LEVEL, Rate
from ..store.payloads import Nominal, WorstPayload, WorstPoint
from ..store.rows import JobRow
from . import figures as F
from .figure_style import param_name
from .html import esc, fmt_num, folded, table
from .integrity import banner_html
from .rows import Context, Section

#: Worst cases shown per report (the gallery, :mod:`.gallery`): the most severe breached images.
WORST_CASES = 12

#: Severity order of an image's breach kinds: misleading (the system does not know: integrity lost) first, then
#: unknown (rows without their points), then flagged only (the system knows it has no fix: availability lost).
_KIND_ORDER: dict[BreachKind | None, int] = {BreachKind.MISLEADING: 0, None: 1, BreachKind.FLAGGED: 2}


@dataclass(frozen=True)
class RiskBound:
    """A risk run's pooled failure probability over a box's images (:func:`vbl_robust.risk.pooled_risk`):
    θ drawn from its distribution, in %, with its interval at ``level``."""

    method: str
    p_fail_pct: float
    ci_pct: tuple[float, float]
    level: float


@dataclass(frozen=True)
class BoxEvidence:
    """One box over every method: coverage, counts with their intervals (in %), bounds and completeness."""

    label: str
    ranges: dict[str, tuple[float, float]]
    methods: tuple[str, ...]
    images: int
    evaluations: int
    survivors: int
    misleading: int | None
    flagged: int | None
    survival_ci: tuple[float, float]
    misleading_ci: tuple[float, float] | None
    residual_bound: float | None
    remaining_area_pct: float | None
    search_status: dict[str, int]
    risk: tuple[RiskBound, ...] = ()
    #: images with a sound bound ≤ ε_safe over the box from some method (:attr:`Verdict.CERTIFIED`)
    certified: int = 0


@dataclass(frozen=True)
class WorstCase:
    """One breached image's most severe breach (:func:`worst_cases`), as the gallery shows it.

    ``worst_m`` = the search's worst error at ``theta`` (θ*, real units); ``kind`` = the job's
    :class:`~vbl_robust.constants.BreachKind` value (None: unknown); ``reason`` = the failure reason at θ* (``""``: a
    pose; None: unknown); ``conf`` = the top candidate's confidence at θ*; ``corners`` = the corners the detector
    predicted at θ* (sample's pixels of the perturbed view, TR TL BL BR; None: none, or not stored);
    ``confident_m`` = the largest error of a confident pose the search found (None without its points): where θ*
    itself is a flagged failure, the misleading pose lies elsewhere in Θ; ``position_sigma_m`` = how sure a detector
    with per-corner σ said it was at θ* (the corners' σ propagated to the position; None: it gives no σ);
    ``nominal_*`` = the same facts unperturbed (θ at its identity: L(0) in metres, the failure reason, confidence
    and predicted corners; None: stored before jobs held them, :func:`vbl_robust.campaigns.work.nominal_details`)."""

    sample_id: str
    box_label: str
    method: str
    budget_label: str | None
    worst_m: float
    theta: dict[str, float] | None
    kind: str | None
    reason: str | None = None
    conf: float | None = None
    corners: tuple[tuple[float, float], ...] | None = None
    confident_m: float | None = None
    position_sigma_m: float | None = None
    nominal_m: float | None = None
    nominal_reason: str | None = None
    nominal_conf: float | None = None
    nominal_corners: tuple[tuple[float, float], ...] | None = None


@dataclass(frozen=True)
class Evidence:
    """Everything :func:`section_evidence` shows; ``level`` is the intervals' confidence level; ``worst`` the
    :data:`WORST_CASES` most severe of the ``breached`` images."""

    experiment: str
    eps_safe_m: float
    level: float
    jobs_done: int
    jobs_planned: int | None
    boxes: tuple[BoxEvidence, ...]
    worst: tuple[WorstCase, ...]
    breached: int = 0
    budget: str | None = None
    #: The jobs the tool could not measure (in no count or rate above): sample, method, box, kind and reason each.
    not_measured: tuple[dict[str, Any], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _risk_bounds(rows: Sequence[JobRow]) -> tuple[RiskBound, ...]:
    from ..analysis.risk import pooled_risk

    return tuple(RiskBound(p.method, 100.0 * p.p_fail, (100.0 * p.ci.low, 100.0 * p.ci.high), float(p.ci.level))
                 for p in pooled_risk(rows))


def _box_evidence(label: str, rows: Sequence[JobRow], eps: float) -> BoxEvidence:
    box = rows[0].box.box if rows[0].box is not None else None
    ids = sorted({r.sample_id for r in rows})
    breached, silent, unknown = br.breached_images(rows, eps)
    survivors = len(ids) - len(breached)
    misleading = None if unknown else len(silent)
    flagged = None if unknown else len(breached - silent)
    surv = Rate(survivors, len(ids))
    bounds = [b for b in (br.residual_bound(r, eps) for r in rows if r.sample_id not in breached) if b is not None]
    ra = [r.trace[-1].remaining_area for r in rows if r.method in direct_family() and r.trace
          and r.trace[-1].remaining_area is not None]
    status: dict[str, int] = {}
    for r in rows:
        key = r.search_status or r.status.value
        status[key] = status.get(key, 0) + 1
    certified = len({r.sample_id for r in rows if r.verdict == Verdict.CERTIFIED} - breached)
    return BoxEvidence(
        label=label, certified=certified, ranges={} if box is None else {n: (float(lo), float(hi)) for n, lo, hi in
                                                   zip(box.names, box.lower, box.upper, strict=True)},
        methods=tuple(dict.fromkeys(r.method for r in rows)), images=len(ids), evaluations=sum(r.nfev for r in rows),
        survivors=survivors, misleading=misleading, flagged=flagged, survival_ci=(surv.ci.low, surv.ci.high),
        misleading_ci=None if misleading is None else (Rate(misleading, len(ids)).ci.low,
                                                       Rate(misleading, len(ids)).ci.high),
        residual_bound=max(bounds) if bounds else None,
        remaining_area_pct=100.0 * float(np.mean(ra)) if ra else None, search_status=dict(sorted(status.items())),
        risk=_risk_bounds(rows),
    )


def confident_m(row: JobRow) -> float | None:
    """The largest error of a confident pose (an evaluation with no failure reason) among the row's points; None
    without points or without such a pose."""
    p = row.points
    if p is None:
        return None
    ok = np.array([not r for r in p.reasons], dtype=bool) & np.isfinite(p.fs)
    return float(p.fs[ok].max()) if ok.any() else None


def worst_cases(rows: Sequence[JobRow], eps: float, penalty_m: float, cap: int = WORST_CASES,
                stored: Mapping[str, JobRow] | None = None,
                nominal: Mapping[str, Nominal] | None = None) -> tuple[list[WorstCase], int]:
    """The ``cap`` most severe breached images of ``rows`` and how many images are breached.

    Each image stands by its most severe row: a misleading breach before an unknown one before a flagged-only one
    (:data:`_KIND_ORDER`), then the larger error (a misleading row's: its largest confident-pose error), then the
    smaller box. Images are ordered the same way. ``stored``: the stored runs by key, for rows read off a trace
    (their corners are those of the run when the read-off budget has the run's worst point); ``nominal``: each
    image's unperturbed facts (:attr:`Context.nominal <vbl_robust.report.rows.Context.nominal>`)."""
    best: dict[str, tuple[tuple[float, float, float], JobRow, BreachKind | None, float | None]] = {}
    for r in rows:
        if br.survived(r, eps):
            continue
        kind = br.breach_kind(r, eps)
        conf_m = confident_m(r)
        err = conf_m if kind == BreachKind.MISLEADING and conf_m is not None else (
            r.worst_m if r.worst_m is not None else penalty_m)
        key = (_KIND_ORDER[kind], -err, r.box_level or 0.0)
        if r.sample_id not in best or key < best[r.sample_id][0]:
            best[r.sample_id] = (key, r, kind, conf_m)
    cases = []
    for _, r, kind, conf_m in sorted(best.values(), key=lambda t: (t[0], t[1].sample_id))[:cap]:
        src = r
        if r.read_from and stored is not None:  # read off a run: its corners hold where its worst point is the run's
            run = stored.get(r.key.removesuffix(f"@{r.budget_label}"))
            src = run if run is not None and run.worst_x == r.worst_x else r
        payload = WorstPayload.of(src)
        worst = WorstPoint() if payload is None else payload.worst
        nom = (nominal or {}).get(r.sample_id) or Nominal()
        cases.append(WorstCase(r.sample_id, r.box_label or "", r.method, r.budget_label,
                               float(r.worst_m if r.worst_m is not None else penalty_m),
                               None if r.worst_x is None else dict(r.worst_x), None if kind is None else kind.value,
                               r.worst_reason, worst.conf, src.worst_corners, conf_m, worst.position_sigma_m,
                               nom.error_m, nom.reason, nom.conf,
                               None if nom.corners is None else tuple((float(u), float(v)) for u, v in nom.corners)))
    return cases, len(best)


def evidence_of(ctx: Context) -> Evidence:
    """The run's :class:`Evidence` from its main rows and its failure-probability rows (rows read off a trace
    included, per budget: each budget is a box's evidence of its own only when the run has one budget; otherwise the
    largest budget stands for it). A run without either (``vbl-robust truth``) stands by its dense grids."""
    rows = [r for r in [*ctx.main, *ctx.risk] if r.chain is None and r.box is not None]
    if not rows:  # a truth run (vbl-robust truth): its dense grids are its searches
        rows = [r for r in ctx.store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
                if r.measured and r.chain is None and r.box is not None]
    budget = None
    if len({r.budget_label for r in rows}) > 1:  # runtime experiments: the evidence of the largest budget
        top = max(rows, key=lambda r: (br.budget_value(r, "max_seconds"), br.budget_value(r, "max_evals")))
        budget = top.budget_label
        rows = [r for r in rows if r.budget_label == budget]
    boxes = {}
    for r in sorted(rows, key=lambda r: r.box_level or 0.0):
        boxes.setdefault(r.box_label, []).append(r)
    stored = None
    if any(r.read_from for r in rows):
        stored = {r.key: r for r in ctx.store.jobs(kind="search", role="main", with_trace=False)}
    cases, breached = worst_cases(rows, ctx.eps, ctx.spec.settings.penalty_m, stored=stored, nominal=ctx.nominal)
    runs = ctx.store.runs()
    return Evidence(experiment=ctx.spec.name, eps_safe_m=ctx.eps, level=LEVEL, jobs_done=ctx.store.count(),
                    jobs_planned=runs[-1].provenance.jobs_total if runs else None,
                    boxes=tuple(_box_evidence(lab, rs, ctx.eps) for lab, rs in boxes.items()), worst=tuple(cases),
                    breached=breached, budget=budget,
                    not_measured=tuple({"sample_id": r.sample_id, "method": r.method, "box": r.box_label,
                                        "kind": r.not_measured.value, "reason": r.not_measured_detail}
                                       for r in ctx.unmeasured))


def _pct_ci(ci: tuple[float, float] | None) -> str:
    return "–" if ci is None else f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def _ranges(b: BoxEvidence) -> str:
    return ", ".join(f"{param_name(n)} ∈ [{fmt_num(lo)}, {fmt_num(hi)}]" for n, (lo, hi) in b.ranges.items())


def _bound_text(b: BoxEvidence) -> str:
    """The bound cell: each risk estimator's pooled p_fail with its interval, else random search's bound on the
    breached share of Θ over its no-breach images."""
    if b.risk:
        return "; ".join(f"p_fail {r.p_fail_pct:.3g} % [{r.ci_pct[0]:.3g}, {r.ci_pct[1]:.3g}] ({r.method}, "
                         f"{100 * r.level:g} %)" for r in b.risk)
    return "–" if b.residual_bound is None else f"< {100 * b.residual_bound:.2g} %"


#: The verdict words of the first screen, per box (:func:`verdict_of`), and their CSS class.
VERDICTS = {"not-safe": "Not safe", "not-shown": "Not shown safe", "safe": "Safe", "none": "Not measured"}


def verdict_of(b: BoxEvidence) -> str:
    """A box's verdict over its images (a key of :data:`VERDICTS`): ``not-safe`` when a search breached an image,
    ``safe`` when every image is certified (a sound bound ≤ ε_safe over the box), ``not-shown`` otherwise (no
    breach found, which proves nothing), ``none`` when no image was measured."""
    if not b.images:
        return "none"
    if b.survivors < b.images:
        return "not-safe"
    return "safe" if b.certified == b.images else "not-shown"


def _whole_pct(v: float) -> str:
    return f"{v:.0f}" if v >= 1 or v == 0 else f"{v:.1g}"


def verdict_sentence(b: BoxEvidence, unit: str, level: float = LEVEL) -> str:
    """One sentence (HTML) per box: the verdict, the images breached (misleading / flagged only), survival with its
    interval and what that interval means at this number of images."""
    key = verdict_of(b)
    head = f'<b class="vw vw-{key}">{VERDICTS[key]}</b> on <b>{esc(b.label)}</b>'
    if key == "none":
        return f"{head}: no {unit} measured (survival –)."
    n, breached = b.images, b.images - b.survivors
    if breached:
        kinds = ("kinds unknown" if b.misleading is None else
                 f"{b.misleading} misleading, {b.flagged} flagged only")
        what = f"{breached} of {n} {unit}s breached ({kinds})"
    elif key == "safe":
        what = f"every one of the {n} {unit}s certified (a sound bound keeps its error ≤ ε_safe over the whole box)"
    else:
        what = (f"no breach found on the {n} {unit}s, which proves nothing by itself"
                + (f" ({b.certified} of {n} certified)" if b.certified else ""))
    lo, hi = b.survival_ci
    surv = (f"survival {_whole_pct(100.0 * b.survivors / n)} %, and with {n} {unit}s it could be anywhere in "
            f"{_whole_pct(lo)}–{_whole_pct(hi)} % ({100 * level:g} % interval)")
    risk = "".join(f"; p_fail under its θ distribution {r.p_fail_pct:.3g} % [{r.ci_pct[0]:.3g}, {r.ci_pct[1]:.3g}] "
                   f"({r.method})" for r in b.risk)
    return f"{head}: {what}; {surv}{risk}."


def _data_text(ctx: Context, dataset: Mapping[str, Any]) -> str:
    """What the images were: synthetic scenes or LARD's, and how many."""
    from pathlib import Path

    src = dataset.get("source") or {}
    kind, unit = src.get("kind"), ctx.spec.unit
    n = dataset.get("n") or src.get("n") or len(ctx.samples)
    if kind == SourceKind.SYNTHETIC:
        return f"{n} synthetic LARD-V2-format approach scenes (not LARD's real images)"
    if kind == SourceKind.LARD:
        return f"{n} LARD images ({esc(Path(str(src.get('csv', ''))).name)})"
    if kind == SourceKind.SYNTHETIC_SEQUENCES:
        return f"{n} synthetic approach sequences"
    if kind == SourceKind.LARD_SEQUENCES:
        return f"{n} LARD approach sequences ({esc(Path(str(src.get('csv', ''))).name)})"
    if kind == SourceKind.TRUTH:
        return f"{len(ctx.samples)} {unit}s of the run it checks ({esc(Path(str(src.get('run', ''))).name)})"
    return f"{n} {unit}s" + (f" ({esc(kind)})" if kind else "")


def audited_line(ctx: Context) -> str:
    """The first screen's line on what was audited: the model (name, short SHA-256, design, input size, engine),
    the data (synthetic or LARD, how many), when the last run ended and the vbl-robust version that ran it."""
    from .sections import detector_facts

    runs = ctx.store.runs()
    if not runs:
        return ""
    last = runs[-1]
    prov = last.provenance
    det = prov.detector or {}
    facts = detector_facts(det)
    if not det.get("design") and det.get("kind") != "oracle":
        facts = "design not recorded" + ("" if facts == "–" else f", {facts}")
    when = (last.finished_at or last.started_at or "")[:16].replace("T", " ")
    return (f'<p class="audited"><b>Model</b> {esc(det.get("name", "?"))} ({esc(facts)}) · <b>data</b> '
            f"{_data_text(ctx, prov.dataset or {})} · <b>run</b> {esc(when)} UTC · <b>vbl-robust</b> "
            f"{esc(prov.code_version or '?')}</p>")


def not_measured_banner(rows: Sequence[JobRow], total: int, unit: str) -> str:
    """The first-screen warning of the jobs the tool could not measure (:func:`~vbl_robust.analysis.breach.
    not_measured_lines`), or ``""`` when it measured every job."""
    lines = br.not_measured_lines(rows, total, unit)
    if not lines:
        return ""
    items = "".join(f"<li>{esc(line)}</li>" for line in lines[1:])
    return (f'<div class="warn banner" role="alert"><p><b>{esc(lines[0].rstrip(":"))}.</b> No number in this '
            f"report counts them: not as breaches, not as survivors. The {unit}s they concern enter the rates only "
            f"through the methods that ran.</p><ul>{items}</ul></div>")


#: The name of the first screen's figure (``figures/safety_per_box.png``): an audit's headline figure.
SAFETY_FIGURE = "safety_per_box"

#: Verdict sentences shown before the rest are folded (a run of many boxes, e.g. every perturbation family).
SENTENCES = 8


def section_evidence(ctx: Context, ev: Evidence) -> Section | None:
    """The first screen of the report (module docstring): per box one sentence (:func:`verdict_sentence`), what
    was audited (:func:`audited_line`), then the table — counts and rates in columns of their own — and the
    completeness; also writes ``evidence.json`` into the report's directory. None when the run has no box with a
    result."""
    import json

    if not ev.boxes and not ev.not_measured and not ctx.store.left_out:
        return None
    atomic_write(ctx.out_dir / "evidence.json", json.dumps(ev.to_dict(), indent=1, default=str))
    unit = ctx.spec.unit
    s = Section("Safe where, and how sure")
    banner = not_measured_banner(ctx.unmeasured, ev.jobs_done, unit)
    if banner:
        s.html.append(banner)
    s.html.extend(banner_html(ctx))  # the rows inconsistent with their own evaluations (not used)
    if ev.boxes:
        if ev.budget:
            s.html.append(f"<p>At the largest budget per {unit}, <b>{esc(ev.budget)}</b> (the other budgets: the "
                          "table per method, box and budget).</p>")
        items = [f"<li>{verdict_sentence(b, unit, ev.level)}</li>" for b in ev.boxes]
        s.html.append(f'<ul class="verdicts">{"".join(items[:SENTENCES])}</ul>')
        if len(items) > SENTENCES:
            s.html.append(folded(f"The other {len(items) - SENTENCES} boxes",
                                 f'<ul class="verdicts">{"".join(items[SENTENCES:])}</ul>'))
    s.html.append(audited_line(ctx))
    if not ev.boxes:
        return s
    lines = []
    for b in ev.boxes:
        measured = b.images > 0
        lines.append({
            "box": b.label, "ranges": _ranges(b), "methods": ", ".join(b.methods), "n": b.images,
            "evals": b.evaluations, "breached": b.images - b.survivors,
            "survival": Rate(b.survivors, b.images).pct if measured else None,
            "survival_ci": _pct_ci(b.survival_ci) if measured else "–",
            "misleading": "?" if b.misleading is None else b.misleading,
            "misleading_ci": "?" if b.misleading is None else _pct_ci(b.misleading_ci) if measured else "–",
            "flagged": "?" if b.flagged is None else b.flagged, "bound": _bound_text(b),
            "ra": b.remaining_area_pct, "certified": b.certified,
            "status": ", ".join(f"{k} {v}" for k, v in b.search_status.items()),
        })
    s.html.append(table(lines, [
        ("box", "box", esc), ("n", f"{unit}s", None), ("breached", "breached", None),
        # soft hyphens (U+00AD): a narrow window may break the long headers
        ("misleading", "mis\u00adleading", None), ("flagged", "flagged only", None), ("survival", "survival %", None),
        ("survival_ci", "survival, 95 % CI (%)", esc), ("misleading_ci", "mis\u00adleading, 95 % CI (%)", esc),
        ("bound", "breached share of Θ", esc),
    ], left=("box", "bound"), cls="headline"))
    article = "an" if unit[0] in "aeiou" else "a"
    s.html.append(
        f'<p class="legend">Per box, over every method together: {article} {unit} <i>survives</i> when no method '
        f"found an error above ε_safe = {ev.eps_safe_m:g} m; <i>breached</i> counts the others. <i>Misleading</i>: "
        "some search found a confident pose (confidence ≥ τ_conf, a PnP position) off by more than ε_safe — "
        "integrity lost, the system does not know. <i>Flagged only</i>: every breach was a failure the system sees "
        "(no detection, low confidence, PnP failed) — availability lost. Intervals: exact (Clopper–Pearson) "
        f"{100 * ev.level:g} % over the {unit}s; they describe {unit}s like the ones drawn, not the searches' "
        "misses. Breached share of Θ: where random search drew k independent uniform θ and found no breach, the "
        "breached part of the box is below 1 − 0.05<sup>1/k</sup> of its volume at 95 % (the largest such bound "
        f"over those {unit}s; DIRECT's and APGD's points are not uniform draws and give none); a risk run's pooled "
        "failure probability p_fail under its θ distribution, with its interval.</p>")
    s.html.append(ctx.figure(
        F.survival_per_box(ev.boxes, eps_safe_m=ev.eps_safe_m, unit=unit), SAFETY_FIGURE,
        f"Per box, the share of {unit}s that survive (green), are breached with a misleading pose (red) or with "
        f"flagged failures only (orange); black: survival's exact {100 * ev.level:g} % interval. The numbers: the "
        "table above."))
    s.html.append("<h3>Completeness</h3>")
    s.html.append(table(lines, [("box", "box", esc), ("ranges", "parameters", esc), ("methods", "methods", esc),
                                ("evals", "evaluations", None), ("certified", f"{unit}s certified", None),
                                ("ra", "mean remaining area RA, last iteration (%)", None),
                                ("status", "how the searches ended (jobs)", esc)],
                        left=("box", "ranges", "methods", "status")))
    planned = f" of {ev.jobs_planned} planned" if ev.jobs_planned else ""
    s.html.append(f"<p>{ev.jobs_done} jobs done{planned}. RA: the share of Θ the DIRECT-family searches had not "
                  "pruned when they stopped (estimated, not sound without a Lipschitz constant; see the zones). "
                  "Certified: a sound bound keeps the error ≤ ε_safe over the whole box (needs a Lipschitz "
                  "constant).</p>")
    return s
