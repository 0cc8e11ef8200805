"""The failure rate of a risk run over its images (``vbl-robust risk``'s table, the report's risk section): per
estimator, the pooled p_fail of the stored risk rows with a valid interval (:func:`pooled_risk`). The estimators
themselves: :mod:`vbl_robust.risk`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..risk import failed
from ..specs.kinds import JobKind, JobStatus
from ..stats import Stratum, stratified_interval
from ..store.payloads import RiskPayload, RiskStratum

__all__ = ["PooledRisk", "pooled_risk"]


def _stored_split(strata: Sequence[RiskStratum]) -> list[tuple[float, float]] | None:
    """The δ split a stored guided result used (None: an older row, written with the even split)."""
    if all(s.share_low is not None for s in strata):
        return [(float(s.share_low), float(s.share_high)) for s in strata]
    return None


@dataclass(frozen=True)
class PooledRisk:
    """One estimator's failure rate over the images of a risk run: the mean of the images' p_fail (θ drawn from
    the distribution, the image uniformly among those audited), its interval ``ci`` at confidence 1 − δ, the
    verdict counts per image, and the evaluations spent."""

    method: str
    images: int
    p_fail: float
    ci: Any
    tau: float
    holds: int
    violated: int
    undecided: int
    evaluations: int


def pooled_risk(rows: Sequence[Any]) -> list[PooledRisk]:
    """Per estimator over the risk rows (``store.jobs(kind="risk", with_points=True)``; rows of other kinds and
    failed jobs are left out) — the operational failure rate over these images, with a valid interval:

    - ``mc``: the first n_min draws of every image (n_min = the fewest any image took; every image takes at least
      the first look's, before any stop, so these draws are not chosen by the stopping rule), pooled: k failures
      of m·n_min independent draws with mean the images' mean p_fail. Their sum is Poisson-binomial, less spread
      than the binomial of the same mean (Hoeffding 1956), so the exact binomial interval is conservative.
    - ``guided``: the mean of the images' stratified estimates; the interval is the mean of their intervals at
      confidence 1 − δ/m each (Bonferroni over the m images).
    """
    from ..stats import Interval, clopper_pearson

    by: dict[str, list[tuple[Any, RiskPayload]]] = {}
    for r in rows:
        if r.kind == JobKind.RISK and r.status == JobStatus.DONE and (p := RiskPayload.of(r)) is not None:
            by.setdefault(r.method, []).append((r, p))
    out = []
    for method, got in by.items():
        rs, info = [r for r, _ in got], [p for _, p in got]
        m, delta, tau = len(rs), float(info[0].delta), float(info[0].tau)
        verdicts = [i.verdict for i in info]
        if method == "mc":
            if any(r.points is None for r in rs):
                raise ValueError("pooled_risk: the mc rows need their points (store.jobs(with_points=True))")
            n_min = min(len(r.points) for r in rs)
            k = sum(int(failed(r.points.fs[:n_min], float(i.eps_safe_m)).sum()) for r, i in got)
            est, ci = k / (m * n_min), clopper_pearson(k, m * n_min, 1.0 - delta)
        else:
            parts = [stratified_interval([Stratum(s.mass, s.k, s.n) for s in i.strata], 1.0 - delta / m,
                                         _stored_split(i.strata)) for i in info]
            est = float(np.mean([p[0] for p in parts]))
            ci = Interval(float(np.mean([p[1].low for p in parts])), float(np.mean([p[1].high for p in parts])),
                          1.0 - delta, "mean of per-image intervals, Bonferroni over the images")
        out.append(PooledRisk(method, m, est, ci, tau, verdicts.count("holds"), verdicts.count("violated"),
                              verdicts.count("undecided"), sum(int(r.nfev) for r in rs)))
    return out
