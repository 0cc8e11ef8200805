"""The report section of a sequence campaign (``CampaignSpec.sustain`` set): errors along each approach.

Drawn from the ``sequence`` payload of the main search jobs (:func:`vbl_robust.campaigns.work.sequence_details`):
per sequence the method whose worst θ sustains the largest error, its per-frame errors against the distance from the
runway threshold beside the unperturbed θ's (:func:`.sequence_figure.plot_errors_along_approach`), and a table
of the breach facts — the worst sustained error and its θ, the longest run of breached frames, and where along the
approach the first run of at least ``sustain`` breached frames (a breach a filter cannot ride out) starts.
"""

from __future__ import annotations

from ..constants import Verdict
from ..store.payloads import SequenceFacts, SequencePayload
from ..store.rows import JobRow
from .html import esc, table
from .rows import Context, Section, theta_text
from .sequence_figure import plot_errors_along_approach


def worst_per_sequence(ctx: Context) -> list[tuple[JobRow, SequencePayload]]:
    """Per sequence (in sample order), the main row whose worst θ sustains the largest error, with its payload (rows
    with a ``sequence`` payload only)."""
    best: dict[str, tuple[JobRow, SequencePayload]] = {}
    for r in ctx.main:
        if (p := SequencePayload.of(r)) is not None and r.worst_m is not None:
            if r.sample_id not in best or r.worst_m > best[r.sample_id][0].worst_m:
                best[r.sample_id] = (r, p)
    return sorted(best.values(), key=lambda rp: rp[0].sample_index)


def section_sequences(ctx: Context) -> Section | None:
    rows = worst_per_sequence(ctx)
    if not rows:
        return None
    k = ctx.spec.settings.sustain
    s = Section(f"Along the approach: errors sustained over {k} frame(s)")
    curves = [{"sequence_id": r.sample_id, "distances_m": list(p.frames.distance_m), "nominal_m": _errors(p.nominal),
               "worst_m": _errors(p.worst)} for r, p in rows]
    fig = plot_errors_along_approach(curves, eps_m=ctx.eps, penalty_m=ctx.spec.settings.penalty_m,
                                     title=f"Error along the approach (sustain k = {k})")
    s.html.append(ctx.figure(fig, "sequence_errors", "Per-frame position error against the distance from the runway "
                             "threshold along each approach: the unperturbed θ (dashed) and the worst θ found over "
                             "all methods (solid)."))
    lines = []
    for r, p in rows:
        w, nom = p.worst, p.nominal
        lines.append({"sample_id": r.sample_id, "frames": w.frames, "verdict": r.verdict,
                      "worst": r.worst_m, "method": r.method, "theta": theta_text(r.worst_x),
                      "longest": w.longest_run_frames, "longest_s": w.longest_run_s,
                      "breached": w.breached_frames, "failed": w.failed_frames,
                      "start": w.breach_start_m, "nominal": nom.sustained_m,
                      "nominal_breached": nom.breached_frames})
    s.html.append(table(lines, [
        ("sample_id", "sequence", None), ("frames", "frames", None), ("verdict", "verdict", None),
        ("worst", "worst sustained (m)", None), ("method", "method", None), ("theta", "at θ", esc),
        ("longest", "longest breached run (frames)", None), ("longest_s", "its span (s)", None),
        ("breached", "breached frames", None), ("failed", "failed frames", None),
        ("start", "lasting breach from (m)", None), ("nominal", "nominal sustained (m)", None),
        ("nominal_breached", "nominal breached frames", None)],
        row_class=lambda ln: "breach" if ln["verdict"] == Verdict.BREACH else "",
        left=("sample_id", "verdict", "method", "theta")))
    return s


def _errors(facts: SequenceFacts) -> list[float]:
    """Per-frame errors of a payload (a None — a non-finite error — drawn at the failure penalty's place: NaN)."""
    return [float("nan") if v is None else float(v) for v in facts.errors_m]
