"""Per-job facts over store rows (:class:`~vbl_robust.store.rows.JobRow`): whether an image survived a box,
the kind of a breach (flagged failure or hazardously misleading pose), what "no breach found" is worth for a
search of uniform points, a row's numeric budget and its failed evaluations per reason.

An image *survives* a box when its worst error is ≤ ε_safe. A job the tool could not complete (not measured:
:attr:`~vbl_robust.store.rows.JobRow.measured` is False) has no survival at all: asking for it raises, and
every group of rows leaves it out of its denominator (:func:`measured_rows`). Re-exported by :mod:`vbl_robust.analysis.metrics`.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Sequence

import numpy as np

from ..constants import BreachKind
from ..specs.kinds import JobStatus
from ..stats import breach_fraction_bound
from ..store.rows import JobRow


def survival_rate(worst: Sequence[float], eps_safe_m: float) -> float:
    """Percentage of images whose worst error is ≤ ``eps_safe_m`` (NaN for no images)."""
    w = np.asarray(worst, dtype=np.float64)
    if w.size == 0:
        return math.nan
    return float(100.0 * np.mean(np.isfinite(w) & (w <= eps_safe_m)))


def measured_rows(rows: Iterable[JobRow]) -> tuple[list[JobRow], list[JobRow]]:
    """``rows`` split into those the tool measured and those it could not (status NOT_MEASURED): only the first
    enter a rate; the second are counted and listed apart."""
    done, not_done = [], []
    for r in rows:
        (done if r.measured else not_done).append(r)
    return done, not_done


def _require_measured(row: JobRow) -> None:
    if not row.measured:
        raise ValueError(f"job {row.method} on {row.sample_id} ({row.box_label}) was not measured "
                         f"({row.reason}): it has no survival and enters no rate")


def empty_row(row: JobRow) -> bool:
    """A search that completed no evaluation within its time budget: it found nothing (:func:`survived`) and has no
    worst error to count in the statistics."""
    return row.status == JobStatus.DONE and row.nfev == 0 and row.worst_m is None


def survived(row: JobRow, eps_safe_m: float) -> bool:
    """Whether the image survived this job: its worst error is finite and ≤ ``eps_safe_m``, or the job completed
    no evaluation (:func:`empty_row`). The one definition behind every survival rate (:func:`summarize`) and paired
    comparison (claims, ``report --compare``; the test is :func:`vbl_robust.stats.paired`). ``ValueError`` for a
    job not measured: it has no survival (leave it out first, :func:`measured_rows`)."""
    _require_measured(row)
    if empty_row(row):
        return True
    return row.worst_m is not None and math.isfinite(row.worst_m) and row.worst_m <= eps_safe_m


def breach_kind(row: JobRow, eps_safe_m: float) -> BreachKind | None:
    """Integrity apart from availability (:class:`~vbl_robust.constants.BreachKind`): ``SAFE`` for a survivor
    (:func:`survived`); ``MISLEADING`` when some evaluation of the job succeeded (no failure reason: a selected
    candidate with confidence ≥ τ_conf and a PnP pose) with a finite error above ``eps_safe_m``; else ``FLAGGED``
    (every breach was a flagged failure). ``ValueError`` for a job not measured.

    Exact from the job's points (``store.jobs(with_points=True)``, as :func:`main_rows` loads them). Without
    them, a job whose worst point is itself a silent breach is ``MISLEADING``; any other breached job is ``None``
    (unknown: a misleading pose may hide below a flagged worst)."""
    if survived(row, eps_safe_m):
        return BreachKind.SAFE
    if row.status != JobStatus.DONE:
        return BreachKind.FLAGGED
    if row.points is None:
        silent_worst = not row.worst_reason and row.worst_m is not None and math.isfinite(row.worst_m)
        return BreachKind.MISLEADING if silent_worst and row.worst_m > eps_safe_m else None
    p = row.points
    ok = np.fromiter((not r for r in p.reasons), dtype=bool, count=len(p))
    with np.errstate(invalid="ignore"):
        silent = ok & np.isfinite(p.fs) & (p.fs > eps_safe_m)
    return BreachKind.MISLEADING if silent.any() else BreachKind.FLAGGED


def breached_images(rows: Iterable[JobRow], eps_safe_m: float) -> tuple[set[str], set[str], bool]:
    """Over every method together (an image is breached when any measured row of it is; rows not measured are left
    out): the breached images, those of them with a misleading pose (:func:`breach_kind`), and whether some breached
    row's kind is unknown (no points)."""
    breached, misleading, unknown = set(), set(), False
    for r in rows:
        if not r.measured or survived(r, eps_safe_m):
            continue
        breached.add(r.sample_id)
        kind = breach_kind(r, eps_safe_m)
        unknown |= kind is None
        if kind == BreachKind.MISLEADING:
            misleading.add(r.sample_id)
    return breached, misleading, unknown


def residual_bound(row: JobRow, eps_safe_m: float) -> float | None:
    """What "no breach found" is worth for a search whose points are independent and uniform over the box
    (``iid_uniform`` methods: random search): with k = ``nfev`` points and no breach, the breached fraction of the
    box is below :func:`vbl_robust.stats.breach_fraction_bound` (k) at 95 % (≈ 3/k). None for a breached row, a
    row of another method (DIRECT's and APGD's points are not uniform draws) or one not run."""
    from ..search.api import METHODS

    cls = METHODS.get(row.method)
    if cls is None or not cls.iid_uniform or row.status != JobStatus.DONE or not survived(row, eps_safe_m):
        return None
    return breach_fraction_bound(int(row.nfev))


def budget_value(row: JobRow, axis: str) -> float:
    """The numeric budget of a row on ``axis`` ("max_seconds", "max_evals", "max_iters") or NaN."""
    v = None if row.budget is None else getattr(row.budget, axis)
    return math.nan if v is None else float(v)


def failure_counts(rows: Iterable[JobRow]) -> dict[str, int]:
    """Failed evaluations per reason over ``rows`` (``{reason: count}``, sorted by reason)."""
    total: Counter[str] = Counter()
    for r in rows:
        total.update(r.failures)
    return dict(sorted(total.items()))


def not_measured_lines(rows: Iterable[JobRow], total: int | None = None, unit: str = "image",
                       limit: int = 8) -> list[str]:
    """What the tool could not measure, for a user to act on: a headline (``"2 of 31 jobs not measured"``) and one
    line per kind and reason with the methods and the number of ``unit`` s it hit (at most ``limit`` lines, then
    how many more); ``[]`` when every job was measured."""
    missing = [r for r in rows if not r.measured]
    if not missing:
        return []
    groups: dict[tuple[str, str], tuple[set[str], set[str]]] = {}
    for r in missing:
        methods, samples = groups.setdefault((r.not_measured.value, r.not_measured_detail), (set(), set()))
        methods.add(r.method)
        samples.add(r.sample_id)
    head = (f"{len(missing)} of {total} jobs" if total else f"{len(missing)} job{'s' * (len(missing) != 1)}") \
        + " not measured"
    lines = [head + " (they enter no rate):"]
    for (kind, detail), (methods, samples) in sorted(groups.items(), key=lambda kv: -len(kv[1][1]))[:limit]:
        lines.append(f"{kind}: {detail} — {', '.join(sorted(methods))} on {len(samples)} {unit}"
                     f"{'s' * (len(samples) != 1)}")
    if len(groups) > limit:
        lines.append(f"… and {len(groups) - limit} more reasons (report.html lists every job)")
    return lines
