"""A search job's optimizer arguments (:func:`search_kwargs`), a search result as the fields of its stored row
(:func:`result_fields`: what the worker writes) and a stored search row as the result it stands for
(:func:`row_result`): what replaying a job (:mod:`.replay`), reading budgets off a trace
(:mod:`vbl_robust.analysis.readoff`) and checking a row against its own evaluations (:mod:`.verify`) rebuild.
Torch-free: what reads a store imports no detector."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..constants import Verdict
from ..search.result import verdict_for
from ..store.rows import JobRow, Points

__all__ = ["finite_or_none", "result_fields", "row_result", "search_kwargs"]


def finite_or_none(v: float | None) -> float | None:
    """``v`` as a float; None when it is None or not finite (what a stored row holds for no value)."""
    return None if v is None or not math.isfinite(v) else float(v)


def result_fields(result: Any, eps_safe_m: float, penalty_m: float) -> dict[str, Any]:
    """The :class:`JobRow` fields of a :class:`~vbl_robust.search.result.SearchResult` (worst error = the penalty when
    no evaluation was finite; None, verdict "no breach found", when none completed within a time budget)."""
    ub = result.upper_bound
    if result.nfev == 0:  # no evaluation completed within the budget: nothing found (no worst error)
        worst, verdict = None, Verdict.NO_BREACH_FOUND
    else:
        worst = float(result.fun) if math.isfinite(result.fun) else penalty_m
        verdict = verdict_for(worst, ub, eps_safe_m)
    return dict(
        worst_m=worst, worst_x=result.x_dict(), verdict=verdict, nfev=int(result.nfev),
        nit=int(result.nit), n_failed=int(result.n_failed), failures=result.failures,
        worst_reason=None if result.x is None else result.x_reason, worst_corners=None,  # set by run_sample_task
        search_status=result.status.value, message=result.message, search_s=float(result.elapsed),
        upper_bound=None if ub is None else (float(ub) if math.isfinite(ub) else 1e300),
        bound_estimate=finite_or_none(result.bound_estimate), lipschitz_estimate=finite_or_none(result.lipschitz_estimate),
        trace=result.trace, points=Points(result.xs, result.fs, result.reasons, result.times),
    )


def row_result(row: JobRow) -> Any:
    """The :class:`~vbl_robust.search.result.SearchResult` a stored search row stands for, rebuilt from its points and
    trace (``row`` needs ``points``: ``store.jobs(with_points=True)``)."""
    from ..search.result import SearchResult, Status

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


def search_kwargs(options: Mapping[str, Any], budget: Any, *, eps_safe_m: float, lipschitz: Any,
                  seed: int | None) -> dict[str, Any]:
    """The optimizer's arguments of a search job apart from its time budget: evaluation and iteration budgets, the
    early stop at ε_safe, the seed and the method's options (the run's ``lipschitz`` unless the job sets one).
    :func:`~vbl_robust.campaigns.work.run_search_job` runs a job with them and :func:`~vbl_robust.campaigns.replay.replay` rebuilds its optimizer."""
    opts = dict(options)
    if lipschitz is not None and "lipschitz" not in opts:
        opts["lipschitz"] = lipschitz  # it changes no point
    return {"max_evals": budget.max_evals, "max_iters": budget.max_iters,
            "stop_above": eps_safe_m if budget.stop_at_breach else None, "seed": seed or 0, **opts}
