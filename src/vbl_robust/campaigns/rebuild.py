"""A stored search row as the search result it stands for (:func:`row_result`): what reading budgets off a trace
(:mod:`vbl_robust.analysis.readoff`) and checking a row against its own evaluations (:mod:`.verify`) both rebuild."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..store import JobRow

__all__ = ["row_result"]


def row_result(row: JobRow) -> Any:
    """The :class:`~vbl_robust.search.SearchResult` a stored search row stands for, rebuilt from its points and
    trace (``row`` needs ``points``: ``store.jobs(with_points=True)``)."""
    from ..search import SearchResult, Status

    if row.points is None or row.box is None:
        raise ValueError(f"row {row.key}: a result needs the row's box and points (load with with_points=True)")
    p = row.points
    finite = np.isfinite(p.fs)
    i = int(np.argmax(np.where(finite, p.fs, -np.inf))) if finite.any() else None
    ub = row.upper_bound
    return SearchResult(
        x=None if i is None else p.xs[i].copy(), fun=math.nan if i is None else float(p.fs[i]), nfev=len(p),
        nit=row.nit, status=Status(row.search_status or "running"), message=row.message or "",
        elapsed=row.search_s or 0.0, trace=row.trace, xs=p.xs, fs=p.fs, method=row.method, names=row.box.box.names,
        seed=row.seed, n_failed=sum(1 for r in p.reasons if r), reasons=p.reasons,
        x_reason="" if i is None else p.reasons[i],
        lipschitz_estimate=row.lipschitz_estimate, bound_estimate=row.bound_estimate,
        upper_bound=None if ub is None else (math.inf if ub >= 1e300 else ub), times=p.times,
    )
