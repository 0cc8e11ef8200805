"""The report section of a risk run (``vbl-robust risk``): per estimator the failure rate pooled over the images
with its interval and the verdict counts, a figure of each image's p_fail with its interval, and the table."""

from __future__ import annotations

from ..analysis.risk import pooled_risk
from ..specs.kinds import JobStatus
from ..store.payloads import RiskPayload
from . import figures as F
from .html import esc, table
from .rows import Context, Section, sample_cols


def section_risk(ctx: Context) -> Section | None:
    rows = [r for r in ctx.risk if r.status == JobStatus.DONE and RiskPayload.of(r) is not None]
    if not rows:
        return None
    info = {r.key: RiskPayload.of(r) for r in rows}
    first = info[rows[0].key]
    tau, level = float(first.tau), 1.0 - float(first.delta)
    s = Section("Failure probability under the θ distribution")
    pooled = pooled_risk(rows)
    s.html.append(
        f"<p>θ drawn from the distribution over the box (see the summary's note); an image fails at θ when its error "
        f"is above ε_safe = {ctx.eps:g} m or the pipeline fails. Per image p_fail with an interval valid at "
        f"{100 * level:g} % (mc: group-sequential exact test, valid however early it stopped; guided: stratified over "
        "a worst-case search's cells, Bonferroni over the strata — statistical, not a sound certificate); verdict on "
        f"p_fail ≤ {tau:g}.</p>")
    s.html.append(table([{"method": p.method, "images": p.images, "p_fail": f"{100 * p.p_fail:.2f}",
                          "ci": f"[{100 * p.ci.low:.2f}, {100 * p.ci.high:.2f}]", "holds": p.holds,
                          "violated": p.violated, "undecided": p.undecided, "evals": p.evaluations} for p in pooled],
                        [("method", "estimator", esc), ("images", "images", None), ("p_fail", "pooled p_fail %", esc),
                         ("ci", f"{100 * level:g} % interval (%)", esc), ("holds", "holds", None),
                         ("violated", "violated", None), ("undecided", "undecided", None),
                         ("evals", "evaluations", None)], left=("method",)))
    s.html.append("<p>Pooled: the failure rate when the image is drawn uniformly among these and θ from the "
                  "distribution (mc: the first draws of every image, before any stop; guided: the mean of per-image "
                  "intervals, Bonferroni over the images).</p>")
    order = {sid: k for k, sid in enumerate(sorted({r.sample_id for r in rows}))}
    series = {m: [(order[r.sample_id], info[r.key].p_fail, info[r.key].ci_low, info[r.key].ci_high)
                  for r in rows if r.method == m]
              for m in dict.fromkeys(r.method for r in rows)}
    s.html.append(ctx.figure(F.risk_per_image(series, len(order), tau), "risk", "Each image's p_fail and interval per estimator; the "
                             "dotted line is τ."))
    lines = []
    for r in sorted(rows, key=lambda r: (r.sample_id, r.method)):
        i = info[r.key]
        lines.append({"sample_id": r.sample_id, **sample_cols(ctx, r.sample_id), "method": r.method,
                      "p_fail": 100 * i.p_fail, "ci": f"[{100 * i.ci_low:.2f}, {100 * i.ci_high:.2f}]",
                      "verdict": i.verdict, "evals": i.evaluations, "worst": r.worst_m,
                      "strata": "; ".join(f"mass {100 * t.mass:.3g} %: {t.k}/{t.n}" for t in i.strata)})
    s.html.append(table(lines, [("sample_id", "image", esc), ("slant_distance_m", "slant dist. (m)", None),
                                ("method", "estimator", esc), ("p_fail", "p_fail %", None), ("ci", "interval (%)", esc),
                                ("verdict", f"p_fail ≤ {tau:g}", esc), ("evals", "evaluations", None),
                                ("worst", "largest error drawn (m)", None), ("strata", "strata: failures/draws", esc)],
                        left=("sample_id", "method", "verdict", "strata")))
    return s
