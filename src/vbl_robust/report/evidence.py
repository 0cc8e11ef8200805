"""The evidence a run gives, organised as a safety case reads it: what was covered, the worst cases found, how sure
the numbers are, and how complete the search was. Worded as evidence, not as a compliance claim.

:func:`evidence_of` computes it from a report :class:`~vbl_robust.report.rows.Context` (nothing is evaluated);
:func:`section_evidence` renders it as the report's first section after the summary, and ``evidence.json`` beside
``report.html`` holds the same numbers (:meth:`Evidence.to_dict`).

Per box, the images are counted over **every method together** (an image is breached when any method found a
breach): survival, misleading and flagged-only images each with their exact 95 % interval
(:class:`vbl_robust.stats.Rate`); for random search, the largest bound over its surviving images on the breached
fraction of the box (:func:`vbl_robust.campaigns.metrics.residual_bound`); for the DIRECT family, the mean remaining
area RA of the last iteration (the share of Θ not yet pruned as below the best value found).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..atomic import atomic_write
from ..campaigns import metrics as mx
from ..campaigns.store import JobRow
from ..search import direct_family
from ..stats import LEVEL, Rate
from .html import esc, fmt_num, table
from .rows import Context, Section, theta_text

#: Worst cases listed per report (most severe first).
WORST_CASES = 10


@dataclass(frozen=True)
class BoxEvidence:
    """One box over every method: coverage, counts with their intervals (in %), and completeness."""

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


@dataclass(frozen=True)
class WorstCase:
    sample_id: str
    box_label: str
    method: str
    worst_m: float
    theta: dict[str, float] | None
    kind: str | None


@dataclass(frozen=True)
class Evidence:
    """Everything :func:`section_evidence` shows; ``level`` is the intervals' confidence level."""

    experiment: str
    eps_safe_m: float
    level: float
    jobs_done: int
    jobs_planned: int | None
    boxes: tuple[BoxEvidence, ...]
    worst: tuple[WorstCase, ...]

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _box_evidence(label: str, rows: Sequence[JobRow], eps: float) -> BoxEvidence:
    box = rows[0].box.box if rows[0].box is not None else None
    ids = sorted({r.sample_id for r in rows})
    breached, silent, unknown = mx.breached_images(rows, eps)
    survivors = len(ids) - len(breached)
    misleading = None if unknown else len(silent)
    flagged = None if unknown else len(breached - silent)
    surv = Rate(survivors, len(ids))
    bounds = [b for b in (mx.residual_bound(r, eps) for r in rows if r.sample_id not in breached) if b is not None]
    ra = [r.trace[-1].remaining_area for r in rows if r.method in direct_family() and r.trace
          and r.trace[-1].remaining_area is not None]
    status: dict[str, int] = {}
    for r in rows:
        key = r.search_status or r.status.value
        status[key] = status.get(key, 0) + 1
    return BoxEvidence(
        label=label, ranges={} if box is None else {n: (float(lo), float(hi)) for n, lo, hi in
                                                   zip(box.names, box.lower, box.upper, strict=True)},
        methods=tuple(dict.fromkeys(r.method for r in rows)), images=len(ids), evaluations=sum(r.nfev for r in rows),
        survivors=survivors, misleading=misleading, flagged=flagged, survival_ci=(surv.ci.low, surv.ci.high),
        misleading_ci=None if misleading is None else (Rate(misleading, len(ids)).ci.low,
                                                       Rate(misleading, len(ids)).ci.high),
        residual_bound=max(bounds) if bounds else None,
        remaining_area_pct=100.0 * float(np.mean(ra)) if ra else None, search_status=dict(sorted(status.items())),
    )


def evidence_of(ctx: Context) -> Evidence:
    """The run's :class:`Evidence` from its main rows (rows read off a trace included, per budget: each budget is
    a box's evidence of its own only when the run has one budget; otherwise the largest budget stands for it)."""
    rows = [r for r in ctx.main if r.chain is None and r.box is not None]
    if len({r.budget_label for r in rows}) > 1:  # runtime experiments: the evidence of the largest budget
        top = max(rows, key=lambda r: (mx.budget_value(r, "max_seconds"), mx.budget_value(r, "max_evals")))
        rows = [r for r in rows if r.budget_label == top.budget_label]
    boxes = {}
    for r in sorted(rows, key=lambda r: r.box_level or 0.0):
        boxes.setdefault(r.box_label, []).append(r)
    worst = sorted((r for r in rows if not mx.survived(r, ctx.eps)),
                   key=lambda r: -(r.worst_m if r.worst_m is not None else ctx.spec.penalty_m))
    seen: set[str] = set()
    cases = []
    for r in worst:  # one line per image: its most severe breach
        if r.sample_id in seen:
            continue
        seen.add(r.sample_id)
        kind = mx.breach_kind(r, ctx.eps)
        cases.append(WorstCase(r.sample_id, r.box_label or "", r.method, float(r.worst_m or ctx.spec.penalty_m),
                               r.worst_x, None if kind is None else kind.value))
        if len(cases) == WORST_CASES:
            break
    runs = ctx.store.runs()
    return Evidence(experiment=ctx.spec.name, eps_safe_m=ctx.eps, level=LEVEL, jobs_done=ctx.store.count(),
                    jobs_planned=runs[-1].get("jobs_total") if runs else None,
                    boxes=tuple(_box_evidence(lab, rs, ctx.eps) for lab, rs in boxes.items()), worst=tuple(cases))


def _pct_ci(ci: tuple[float, float] | None) -> str:
    return "–" if ci is None else f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def _ranges(b: BoxEvidence) -> str:
    return ", ".join(f"{n} ∈ [{fmt_num(lo)}, {fmt_num(hi)}]" for n, (lo, hi) in b.ranges.items())


def section_evidence(ctx: Context) -> Section | None:
    """The evidence section (module docstring); also writes ``evidence.json`` into the report's directory."""
    import json

    ev = evidence_of(ctx)
    if not ev.boxes:
        return None
    atomic_write(ctx.out_dir / "evidence.json", json.dumps(ev.to_dict(), indent=1, default=str))
    unit = ctx.spec.unit
    s = Section("Evidence: safe where, and how sure")
    s.html.append(
        f"<p>Per box, over every method together: {'an' if unit[0] in 'aeiou' else 'a'} {unit} is <i>breached</i> "
        "when any method found an error above "
        f"ε_safe = {ev.eps_safe_m:g} m. <i>Misleading</i>: some search found a confident pose (confidence ≥ τ_conf, "
        "a PnP position) off by more than ε_safe — integrity lost, the system does not know. <i>Flagged only</i>: "
        "every breach was a failure the system sees (no detection, low confidence, PnP failed) — availability "
        f"lost. Intervals: exact (Clopper–Pearson) {100 * ev.level:g} % over the {unit}s; they describe the {unit}s "
        "drawn, not the searches' misses.</p>")
    lines = []
    for b in ev.boxes:
        lines.append({
            "box": b.label, "ranges": _ranges(b), "methods": ", ".join(b.methods), "n": b.images,
            "evals": b.evaluations,
            "survival": f"{Rate(b.survivors, b.images).pct:.1f} {_pct_ci(b.survival_ci)}",
            "misleading": "?" if b.misleading is None else f"{b.misleading} {_pct_ci(b.misleading_ci)}",
            "flagged": "?" if b.flagged is None else str(b.flagged),
            "residual": "–" if b.residual_bound is None else f"< {100 * b.residual_bound:.2g} %",
            "ra": b.remaining_area_pct,
            "status": ", ".join(f"{k} {v}" for k, v in b.search_status.items()),
        })
    s.html.append("<h3>Coverage and statistical bounds</h3>")
    s.html.append(table(lines, [
        ("box", "box", esc), ("ranges", "parameters", esc), ("methods", "methods", esc), ("n", f"{unit}s", None),
        ("evals", "evaluations", None), ("survival", "survival % [95 % CI]", esc),
        ("misleading", f"misleading {unit}s [95 % CI, %]", esc), ("flagged", "flagged only", esc),
        ("residual", "breached share of Θ, random search's no-breach images (95 %)", esc),
    ], left=("box", "ranges", "methods")))
    s.html.append(
        "<p>Breached share of Θ: where random search drew k independent uniform θ and found no breach, the breached "
        "part of the box is below 1 − 0.05<sup>1/k</sup> of its volume at 95 % (the largest such bound over those "
        f"{unit}s). A search that found nothing says only this much; DIRECT's and APGD's points are not uniform "
        "draws and give no such bound.</p>")
    s.html.append("<h3>Completeness</h3>")
    s.html.append(table(lines, [("box", "box", esc), ("ra", "mean remaining area RA, last iteration (%)", None),
                                ("status", "how the searches ended (jobs)", esc)], left=("box", "status")))
    planned = f" of {ev.jobs_planned} planned" if ev.jobs_planned else ""
    s.html.append(f"<p>{ev.jobs_done} jobs done{planned}. RA: the share of Θ the DIRECT-family searches had not "
                  "pruned when they stopped (estimated, not sound without a Lipschitz constant; see the zones).</p>")
    if ev.worst:
        s.html.append(f"<h3>Worst cases ({len(ev.worst)} most severe {unit}s)</h3>")
        s.html.append(table([{**dataclasses.asdict(w), "theta": theta_text(w.theta)} for w in ev.worst], [
            ("sample_id", unit, esc), ("box_label", "box", esc), ("method", "found by", esc),
            ("worst_m", "error (m)", None), ("theta", "at θ", esc), ("kind", "kind", esc)],
            left=("sample_id", "box_label", "method", "theta", "kind")))
    return s

