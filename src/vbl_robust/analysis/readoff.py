"""Budgets read off a trace: a stored run whose budget reads smaller budgets (``Budget.reads``, the runtime
experiments' anytime methods) stands for one result per read budget; :func:`read_off_rows` derives those rows
(``JobRow.read_from`` = the run's budget label) from the run's stamped evaluations
(:func:`vbl_robust.search.anytime.at_budget`): at a time budget t only the evaluations completed by t count.
Re-exported by :mod:`vbl_robust.analysis.metrics`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..campaigns.rebuild import result_fields, row_result
from ..specs.budget import Budget
from ..specs.kinds import JobStatus
from ..store.rows import JobRow, Points

__all__ = ["main_rows", "read_off", "read_off_rows", "reads_trace"]


def read_off(row: JobRow, budget: Budget, eps_safe_m: float, penalty_m: float) -> JobRow:
    """The row of ``budget`` (a time or an evaluation budget) read off the stored run ``row`` (with points): the
    best value and point, counts and trace of the evaluations within the budget; ``read_from`` = the run's
    budget label. A run not measured gives a row not measured for the budget."""
    from ..search.anytime import at_budget

    base = row.replace(budget=budget, key=f"{row.key}@{budget.label}", read_from=row.budget_label, payload=None)
    if row.status != JobStatus.DONE:
        return base
    r = at_budget(row_result(row), seconds=budget.max_seconds, evals=budget.max_evals)
    fields = result_fields(r, eps_safe_m, penalty_m)
    if row.points is not None and row.points.times is None:
        fields["points"] = Points(r.xs, r.fs, r.reasons)
    return base.replace(**fields)


def read_off_rows(rows: Iterable[JobRow], eps_safe_m: float, penalty_m: float) -> list[JobRow]:
    """``rows`` with every run that reads smaller budgets (``row.budget.reads``) replaced by one row per read
    budget (:func:`read_off`; such rows need their points); other rows unchanged, order kept."""
    out: list[JobRow] = []
    for r in rows:
        if r.budget is None or not r.budget.reads:
            out.append(r)
            continue
        out.extend(read_off(r, b, eps_safe_m, penalty_m) for b in r.budget.read_budgets())
    return out


def reads_trace(spec: Any) -> bool:
    """True when a campaign spec holds a budget read off a trace (its main rows need :func:`read_off_rows`)."""
    return any(b.reads for blk in spec.blocks for b in blk.budgets)


def main_rows(store: Any, spec: Any, *, with_trace: bool = True, measured_only: bool = True) -> list[JobRow]:
    """The main search rows of a campaign as its tables and figures show them: stored rows with their points (the
    kind of each breach, :func:`breach_kind`), with every run that reads smaller budgets off its trace replaced by
    its read-off rows (:func:`read_off_rows`). Rows not measured (the tool could not complete them) are left out
    unless ``measured_only`` is False (a summary table that counts them apart, :func:`summarize`). Rows inconsistent
    with their own evaluations or their digests are never used (:func:`vbl_robust.campaigns.verify.screen`: the store
    leaves them out from then on, the report counts them apart)."""
    from ..campaigns.verify import screen

    screen(store, spec)
    reads = reads_trace(spec)
    rows = store.jobs(kind="search", role="main", with_points=True, with_trace=with_trace or reads)
    if measured_only:
        rows = [r for r in rows if r.measured]
    return read_off_rows(rows, spec.settings.eps_safe_m, spec.settings.penalty_m) if reads else rows
