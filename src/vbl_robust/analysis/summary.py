"""Survival tables over store rows: :class:`Summary` per group of rows (:func:`summarize`) and the table column
rule of several budgets (:func:`columns`). Re-exported by :mod:`vbl_robust.analysis.metrics`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..constants import BreachKind, Verdict
from ..stats import Rate
from ..store.rows import JobRow
from .breach import (
    breach_kind,
    budget_value,
    empty_row,
    failure_counts,
    measured_rows,
    residual_bound,
    survived,
)


def _stats(values: Sequence[float]) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {"median": math.nan, "mean": math.nan}
    return {"median": float(np.median(v)), "mean": float(np.mean(v))}

#: The :class:`JobRow` attributes :func:`summarize` can group by.
GROUP_BY = ("method", "box_label", "budget_label", "box_level")


@dataclass(frozen=True)
class Summary:
    """One group of :func:`summarize`.

    Attributes:
        method, box_label, budget_label, box_level: the group's value of each attribute it is grouped by (None for
            one it is not grouped by; ``box_level`` is the first row's when not grouped by it).
        max_evals, max_seconds, max_iters: the group's numeric budget (NaN when the budget has no such bound).
        n: rows measured (images, or sequences); survivors: rows that survived (:func:`survived`); survival: S_rate
            = 100 · survivors / n (%; NaN when no row was measured), with its exact 95 % interval ``survival_ci``
            (:mod:`vbl_robust.stats`); not_measured: rows the tool could not complete (never in ``n`` or any rate);
            n_empty: rows with no evaluation completed within their time budget (survivors, left out of the
            worst-error statistics).
        flagged, misleading: breached rows whose every breach was a flagged failure / that hold a hazardously
            misleading pose (:func:`breach_kind`); None when some breached row's kind is unknown (no points).
        residual: for a method of independent uniform points, the largest :func:`residual_bound` over the rows
            without a breach — on each of them the breached fraction of the box is below it at 95 %; None
            otherwise (or when every row breached).
        median_worst_m, mean_worst_m: over the rows with a worst error (NaN for none).
        breaches, certified: verdict counts.
        nfev, mean_nfev: evaluations in all and per row; failed_evals: failed evaluations (None when no row
            recorded them), failures: per reason.
        median_search_s: median search seconds; read_from: the budget label of the runs the group was read off
            (:func:`read_off_rows`; "" for runs of their own).
    """

    method: str | None
    box_label: str | None
    budget_label: str | None
    box_level: float | None
    max_evals: float
    max_seconds: float
    max_iters: float
    n: int
    survivors: int
    survival: float
    not_measured: int
    n_empty: int
    flagged: int | None
    misleading: int | None
    residual: float | None
    median_worst_m: float
    mean_worst_m: float
    breaches: int
    certified: int
    nfev: int
    mean_nfev: float
    failed_evals: int | None
    failures: Mapping[str, int]
    median_search_s: float
    read_from: str

    @property
    def survival_rate(self) -> Rate:
        """Survivors of n with the exact interval (:class:`vbl_robust.stats.Rate`)."""
        return Rate(self.survivors, self.n)

    @property
    def measured(self) -> bool:
        """Whether some row of the group was measured (else it has no survival: a dash, never 0 % or 100 %)."""
        return self.n > 0

    def kind_rate(self, kind: BreachKind) -> Rate | None:
        """Rows of ``kind`` of n (None when the kinds are unknown or no row was measured)."""
        count = {BreachKind.SAFE: self.survivors, BreachKind.FLAGGED: self.flagged,
                 BreachKind.MISLEADING: self.misleading}[kind]
        return None if count is None or not self.n else Rate(count, self.n)

    def as_row(self) -> dict[str, Any]:
        """The fields by name, plus ``survival_ci_low`` / ``survival_ci_high`` (%, exact 95 %) and
        ``misleading_pct`` / ``flagged_pct`` (for the report's, the command line's and the exported tables)."""
        row = {f.name: getattr(self, f.name) for f in fields(self)}
        ci = self.survival_rate.ci if self.n else None
        row.update(survival_ci_low=math.nan if ci is None else ci.low, survival_ci_high=math.nan if ci is None else ci.high)
        for kind in (BreachKind.FLAGGED, BreachKind.MISLEADING):
            r = self.kind_rate(kind)
            row[f"{kind.value}_pct"] = math.nan if r is None else r.pct
        return row

    def budget(self, axis: str) -> float:
        """The numeric budget on ``axis`` ("max_seconds", "max_evals", "max_iters"), NaN when unbounded there."""
        if axis not in ("max_seconds", "max_evals", "max_iters"):
            raise ValueError(f"axis must be max_seconds, max_evals or max_iters, got {axis!r}")
        return getattr(self, axis)


def columns(rows: Sequence[JobRow]) -> tuple[bool, Callable[[Any], str]]:
    """Whether ``rows`` hold several budgets, and the table column of a row (or of a :class:`Summary` grouped by
    box and budget): its box label, followed by its budget label where there are several (the runtime
    experiments: a survival pooled over budgets would mean nothing). The one rule of ``report --format md`` and
    of the paired comparison (``--compare``)."""
    several = len({r.budget_label for r in rows}) > 1

    def column(r: Any) -> str:
        return f"{r.box_label}, {r.budget_label}" if several else str(r.box_label)

    return several, column


def summarize(rows: Iterable[JobRow], eps_safe_m: float,
              by: Sequence[str] = ("method", "box_label", "budget_label")) -> list[Summary]:
    """One :class:`Summary` per group of ``rows`` with equal ``by`` attributes (names from :data:`GROUP_BY`), in
    first-seen order. A row with no evaluation completed within its time budget (``nfev == 0``, no worst error)
    counts as a survivor (nothing found) and is left out of the worst-error statistics (``n_empty`` counts them). A
    row not measured enters no statistic of its group: ``not_measured`` counts it (a group of such rows only has
    ``n == 0`` and no survival)."""
    bad = [k for k in by if k not in GROUP_BY]
    if bad:
        raise ValueError(f"summarize: cannot group by {bad}; groups are {GROUP_BY}")
    groups: dict[tuple, list[JobRow]] = {}
    for r in rows:
        groups.setdefault(tuple(getattr(r, k) for k in by), []).append(r)
    out = []
    for key, every in groups.items():
        rs, unmeasured = measured_rows(every)
        # a search that completed no evaluation within its time budget found nothing: a survivor, and not part
        # of the worst-error statistics
        empty = [empty_row(r) for r in rs]
        worst = [-math.inf if e else r.worst_m for r, e in zip(rs, empty, strict=True)]
        s = _stats([w for w, e in zip(worst, empty, strict=True) if not e])
        known = [r.n_failed for r in rs if r.n_failed is not None]
        group = dict(zip(by, key, strict=True))
        alive = [survived(r, eps_safe_m) for r in rs]
        kinds = [breach_kind(r, eps_safe_m) for r, ok in zip(rs, alive, strict=True) if not ok]
        kinds_known = None not in kinds
        bounds = [b for b in (residual_bound(r, eps_safe_m) for r in rs) if b is not None]
        out.append(Summary(
            method=group.get("method"), box_label=group.get("box_label"), budget_label=group.get("budget_label"),
            box_level=group.get("box_level", every[0].box_level),
            max_evals=budget_value(every[0], "max_evals"), max_seconds=budget_value(every[0], "max_seconds"),
            max_iters=budget_value(every[0], "max_iters"),
            n=len(rs), survivors=sum(alive), survival=100.0 * float(np.mean(alive)) if rs else math.nan,
            not_measured=len(unmeasured), n_empty=sum(empty),
            flagged=kinds.count(BreachKind.FLAGGED) if kinds_known else None,
            misleading=kinds.count(BreachKind.MISLEADING) if kinds_known else None,
            residual=max(bounds) if bounds else None,
            median_worst_m=s["median"], mean_worst_m=s["mean"],
            breaches=sum(r.verdict == Verdict.BREACH for r in rs),
            certified=sum(r.verdict == Verdict.CERTIFIED for r in rs),
            nfev=sum(r.nfev for r in rs), mean_nfev=float(np.mean([r.nfev for r in rs])) if rs else math.nan,
            failed_evals=sum(known) if known else None, failures=failure_counts(rs),
            median_search_s=float(np.median([r.search_s or 0.0 for r in rs])) if rs else math.nan,
            read_from=next((r.read_from for r in rs if r.read_from), ""),
        ))
    return out
