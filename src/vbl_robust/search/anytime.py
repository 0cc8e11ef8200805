"""Read a search's result at a smaller time or evaluation budget off its stamped evaluations.

Every evaluation of a search carries the time its chunk completed (:attr:`SearchResult.times`, seconds on the
search's clock, which starts at the first ``ask`` and so covers the method's own work). The result *at* a time
budget ``t`` counts only the evaluations completed by ``t``; at an evaluation budget ``n``, the first ``n``
evaluations. For an *anytime* method (``Optimizer.anytime``: the points it asks for do not depend on its budget —
the DIRECT family, random, Sobol, grid) that is exactly what a run stopped at that budget would give, so one run
at the largest budget answers every smaller one (a time budget exactly when the run sized its chunks against it,
``maximize(time_marks=...)``, and up to timing noise otherwise).

Evaluation budgets read off a DIRECT-family run are its first ``n`` evaluations; a run started with
``max_evals=n`` instead fits its last iteration to the budget (it divides only the potentially optimal
rectangles whose children all fit), so its last batch can differ.

>>> import numpy as np
>>> from vbl_robust.space import ParameterBox
>>> from vbl_robust.search.api import maximize
>>> r = maximize(lambda x: -(x[:, 0] - 0.3) ** 2, ParameterBox({"a": (-1, 1)}), "random", max_evals=100)
>>> r20 = at_budget(r, evals=20)
>>> r20.nfev, bool(np.array_equal(r20.xs, r.xs[:20])), r20.status.value
(20, True, 'budget_exhausted')
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .result import PARTIAL, SearchResult, Status, TraceRow

__all__ = ["at_budget", "prefix_length"]


def prefix_length(times: np.ndarray | None, n: int, *, seconds: float | None = None, evals: int | None = None) -> int:
    """How many of ``n`` evaluations (stamped ``times``, non-decreasing) count at the budget: those completed by
    ``seconds`` and among the first ``evals``."""
    k = n if evals is None else min(n, int(evals))
    if seconds is not None:
        if times is None:
            raise ValueError("at_budget: a time budget needs the evaluations' time stamps (result.times is None)")
        late = np.flatnonzero(np.asarray(times[:k], dtype=np.float64) > float(seconds))
        k = int(late[0]) if len(late) else k
    return k


def at_budget(result: SearchResult, *, seconds: float | None = None, evals: int | None = None) -> SearchResult:
    """``result`` as it stood at the time budget ``seconds`` and/or evaluation budget ``evals``.

    Counts the evaluations completed by ``seconds`` (stamps ``result.times``) among the first ``evals``: their
    best value and point, counts and failures, the trace rows of the batches completed within the budget and,
    for a batch cut by it, one row marked ``extra["partial"]``. When the budget cuts nothing, ``result`` comes
    back unchanged but for a re-built cut row of its own. A cut result's status is TIME_OUT (time) or
    BUDGET_EXHAUSTED (evaluations), its ``elapsed`` the completion time of its last counted evaluation, and its
    ``upper_bound`` / estimates those of its last complete batch.
    """
    if seconds is None and evals is None:
        raise ValueError("at_budget: give seconds= and/or evals=")
    if seconds is not None and not (math.isfinite(seconds) and seconds >= 0):
        raise ValueError(f"at_budget: seconds must be a finite number >= 0, got {seconds!r}")
    if evals is not None and (not isinstance(evals, int | np.integer) or isinstance(evals, bool) or evals < 0):
        raise ValueError(f"at_budget: evals must be an integer >= 0, got {evals!r}")
    n = int(result.nfev)
    k = prefix_length(result.times, n, seconds=seconds, evals=evals)
    has_partial = any(t.extra.get(PARTIAL) for t in result.trace)
    if k == n and not has_partial:
        return result
    xs, fs = result.xs[:k], result.fs[:k]
    reasons = tuple(result.reasons[:k]) if result.reasons else ("",) * k
    times = None if result.times is None else result.times[:k]
    finite = np.isfinite(fs)
    if finite.any():
        i = int(np.argmax(np.where(finite, fs, -np.inf)))
        x, fun, x_reason = xs[i].copy(), float(fs[i]), reasons[i]
    else:
        x, fun, x_reason = None, math.nan, ""
    n_failed = sum(1 for r in reasons if r)
    kept = [t for t in result.trace if t.nfev <= k and not t.extra.get(PARTIAL)]
    trace = list(kept)
    done = kept[-1].nfev if kept else 0
    if k > done:
        trace.append(TraceRow(iteration=len(kept) + 1, nfev=k, elapsed=float(times[k - 1]) if times is not None else
                              math.nan, best_value=fun, best_x=None if x is None else tuple(float(a) for a in x),
                              batch_size=k - done, n_failed=n_failed, extra={PARTIAL: True}))
    last = kept[-1] if kept else None
    common = dict(x=x, fun=fun, nfev=k, nit=len(trace), trace=tuple(trace), xs=xs, fs=fs, n_failed=n_failed,
                  reasons=reasons, x_reason=x_reason, times=times)
    if k == n:  # nothing cut: only the cut row of a time-stopped run was re-built
        return replace(result, **common)
    by_time = seconds is not None and (evals is None or k < min(n, int(evals)))
    status = Status.TIME_OUT if by_time else Status.BUDGET_EXHAUSTED
    ran = f" (the run went on to {n} evaluations, {result.elapsed:.3g} s)"
    message = (f"max_seconds={seconds:g}: {k} evaluations completed by then" if by_time
               else f"max_evals={evals}: the first {k} evaluations") + ran
    return replace(
        result, **common, status=status, message=message,
        elapsed=float(times[k - 1]) if (k and times is not None) else 0.0,
        upper_bound=None if last is None else last.upper_bound,
        lipschitz_estimate=None if last is None else last.lipschitz_estimate,
        bound_estimate=None if last is None else last.bound_estimate,
    )
