"""The paper's metrics over store rows (:class:`~vbl_robust.campaigns.store.JobRow`): survival rate, median worst
error, φ_crit, |PO_k| and RA(k), failed evaluations per reason, PnP errors, the perturbation families' survival
per budget level and their ranking.

Conventions: a row's ``worst_m`` is the worst error the search found for that image (metres); a failed sample
counts with the failure penalty (5000 m by default), so it is never a survivor. An image *survives* a box when
its worst error is ≤ ε_safe: S_rate = 100 · #survivors / N (%).

Budgets read off a trace: a stored run whose budget reads smaller budgets (``Budget.reads``, the runtime
experiments' anytime methods) stands for one result per read budget; :func:`read_off_rows` derives those rows
(``JobRow.read_from`` = the run's budget label) from the run's stamped evaluations
(:func:`vbl_robust.search.at_budget`): at a time budget t only the evaluations completed by t count.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..constants import BreachKind, Verdict
from ..stats import Rate, breach_fraction_bound, paired
from .spec import BoxSpec, Budget
from .store import JobRow, JobStatus, Points

#: ``method`` of the pseudo-rows of :func:`reference_rows`.
REFERENCE_METHOD = "grid (reference)"


def survival_rate(worst: Sequence[float], eps_safe_m: float) -> float:
    """Percentage of images whose worst error is ≤ ``eps_safe_m`` (NaN for no images)."""
    w = np.asarray(worst, dtype=np.float64)
    if w.size == 0:
        return math.nan
    return float(100.0 * np.mean(np.isfinite(w) & (w <= eps_safe_m)))


def empty_row(row: JobRow) -> bool:
    """A search that completed no evaluation within its time budget: it found nothing (:func:`survived`) and has no
    worst error to count in the statistics."""
    return row.status is JobStatus.DONE and row.nfev == 0 and row.worst_m is None


def survived(row: JobRow, eps_safe_m: float) -> bool:
    """Whether the image survived this job: its worst error is finite and ≤ ``eps_safe_m``, or the job completed
    no evaluation (:func:`empty_row`); a failed job (worst = the penalty) never survives. The one definition behind
    every survival rate (:func:`summarize`) and paired comparison (claims, ``report --compare``; the test is
    :func:`vbl_robust.stats.paired`)."""
    if empty_row(row):
        return True
    if row.status is JobStatus.FAILED:
        return False
    return row.worst_m is not None and math.isfinite(row.worst_m) and row.worst_m <= eps_safe_m


def breach_kind(row: JobRow, eps_safe_m: float) -> BreachKind | None:
    """Integrity apart from availability (:class:`~vbl_robust.constants.BreachKind`): ``SAFE`` for a survivor
    (:func:`survived`); ``MISLEADING`` when some evaluation of the job succeeded (no failure reason: a selected
    candidate with confidence ≥ τ_conf and a PnP pose) with a finite error above ``eps_safe_m``; else ``FLAGGED``
    (every breach was a flagged failure; a job that could not run at all is flagged too).

    Exact from the job's points (``store.jobs(with_points=True)``, as :func:`main_rows` loads them). Without
    them, a job whose worst point is itself a silent breach is ``MISLEADING``; any other breached job is ``None``
    (unknown: a misleading pose may hide below a flagged worst)."""
    if survived(row, eps_safe_m):
        return BreachKind.SAFE
    if row.status is not JobStatus.DONE:
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
    """Over every method together (an image is breached when any row of it is): the breached images, those of them
    with a misleading pose (:func:`breach_kind`), and whether some breached row's kind is unknown (no points)."""
    breached, misleading, unknown = set(), set(), False
    for r in rows:
        if survived(r, eps_safe_m):
            continue
        breached.add(r.sample_id)
        kind = breach_kind(r, eps_safe_m)
        unknown |= kind is None
        if kind is BreachKind.MISLEADING:
            misleading.add(r.sample_id)
    return breached, misleading, unknown


def residual_bound(row: JobRow, eps_safe_m: float) -> float | None:
    """What "no breach found" is worth for a search whose points are independent and uniform over the box
    (``iid_uniform`` methods: random search): with k = ``nfev`` points and no breach, the breached fraction of the
    box is below :func:`vbl_robust.stats.breach_fraction_bound` (k) at 95 % (≈ 3/k). None for a breached row, a
    row of another method (DIRECT's and APGD's points are not uniform draws) or one not run."""
    from ..search.api import METHODS

    cls = METHODS.get(row.method)
    if cls is None or not cls.iid_uniform or row.status is not JobStatus.DONE or not survived(row, eps_safe_m):
        return None
    return breach_fraction_bound(int(row.nfev))


def _stats(values: Sequence[float]) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return {"median": math.nan, "mean": math.nan}
    return {"median": float(np.median(v)), "mean": float(np.mean(v))}


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


#: The :class:`JobRow` attributes :func:`summarize` can group by.
GROUP_BY = ("method", "box_label", "budget_label", "box_level")


@dataclass(frozen=True)
class Summary:
    """One group of :func:`summarize`.

    Attributes:
        method, box_label, budget_label, box_level: the group's value of each attribute it is grouped by (None for
            one it is not grouped by; ``box_level`` is the first row's when not grouped by it).
        max_evals, max_seconds, max_iters: the group's numeric budget (NaN when the budget has no such bound).
        n: rows (images, or sequences); survivors: rows that survived (:func:`survived`); survival: S_rate =
            100 · survivors / n (%), with its exact 95 % interval ``survival_ci`` (:mod:`vbl_robust.stats`);
            n_empty: rows with no evaluation completed within their time budget (survivors, left out of the
            worst-error statistics).
        flagged, misleading: breached rows whose every breach was a flagged failure / that hold a hazardously
            misleading pose (:func:`breach_kind`); None when some breached row's kind is unknown (no points).
        residual: for a method of independent uniform points, the largest :func:`residual_bound` over the rows
            without a breach — on each of them the breached fraction of the box is below it at 95 %; None
            otherwise (or when every row breached).
        median_worst_m, mean_worst_m: over the rows with a worst error (NaN for none).
        breaches, certified, failed: verdict and status counts.
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
    n_empty: int
    flagged: int | None
    misleading: int | None
    residual: float | None
    median_worst_m: float
    mean_worst_m: float
    breaches: int
    certified: int
    failed: int
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

    def kind_rate(self, kind: BreachKind) -> Rate | None:
        """Rows of ``kind`` of n (None when the kinds are unknown)."""
        count = {BreachKind.SAFE: self.survivors, BreachKind.FLAGGED: self.flagged,
                 BreachKind.MISLEADING: self.misleading}[kind]
        return None if count is None else Rate(count, self.n)

    def as_row(self) -> dict[str, Any]:
        """The fields by name, plus ``survival_ci_low`` / ``survival_ci_high`` (%, exact 95 %) and
        ``misleading_pct`` / ``flagged_pct`` (for the report's, the command line's and the exported tables)."""
        row = {f.name: getattr(self, f.name) for f in fields(self)}
        ci = self.survival_rate.ci
        row.update(survival_ci_low=ci.low, survival_ci_high=ci.high)
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
    counts as a survivor (nothing found) and is left out of the worst-error statistics (``n_empty`` counts them)."""
    bad = [k for k in by if k not in GROUP_BY]
    if bad:
        raise ValueError(f"summarize: cannot group by {bad}; groups are {GROUP_BY}")
    groups: dict[tuple, list[JobRow]] = {}
    for r in rows:
        groups.setdefault(tuple(getattr(r, k) for k in by), []).append(r)
    out = []
    for key, rs in groups.items():
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
            box_level=group.get("box_level", rs[0].box_level),
            max_evals=budget_value(rs[0], "max_evals"), max_seconds=budget_value(rs[0], "max_seconds"),
            max_iters=budget_value(rs[0], "max_iters"),
            n=len(rs), survivors=sum(alive), survival=100.0 * float(np.mean(alive)), n_empty=sum(empty),
            flagged=kinds.count(BreachKind.FLAGGED) if kinds_known else None,
            misleading=kinds.count(BreachKind.MISLEADING) if kinds_known else None,
            residual=max(bounds) if bounds else None,
            median_worst_m=s["median"], mean_worst_m=s["mean"],
            breaches=sum(r.verdict is Verdict.BREACH for r in rs),
            certified=sum(r.verdict is Verdict.CERTIFIED for r in rs),
            failed=sum(r.status is JobStatus.FAILED for r in rs),
            nfev=sum(r.nfev for r in rs), mean_nfev=float(np.mean([r.nfev for r in rs])),
            failed_evals=sum(known) if known else None, failures=failure_counts(rs),
            median_search_s=float(np.median([r.search_s or 0.0 for r in rs])),
            read_from=next((r.read_from for r in rs if r.read_from), ""),
        ))
    return out


def _inside(x: np.ndarray, lower: Sequence[float], upper: Sequence[float]) -> np.ndarray:
    """Rows of ``x`` (N, d) inside the box ``[lower, upper]`` (1e-9 tolerance: grid nodes sit on box edges)."""
    return np.all((x >= np.asarray(lower) - 1e-9) & (x <= np.asarray(upper) + 1e-9), axis=1)


def worst_within(xs: np.ndarray, fs: np.ndarray, lower: Sequence[float], upper: Sequence[float],
                 penalty_m: float) -> float:
    """Largest value among the evaluated points inside the box ``[lower, upper]`` (failed values count as the
    penalty; NaN when no point is inside). Used to restrict a dense grid to a nested sub-box."""
    x = np.asarray(xs, dtype=np.float64)
    if x.size == 0:
        return math.nan
    inside = _inside(x, lower, upper)
    if not inside.any():
        return math.nan
    f = np.where(np.isfinite(fs), fs, penalty_m)[inside]
    return float(np.max(f))


def lattice_covered(xs: np.ndarray, grid_bounds: Sequence[Sequence[float]], counts: Sequence[int],
                    lower: Sequence[float], upper: Sequence[float]) -> bool:
    """True if every node of the lattice (``counts`` nodes per dimension over ``grid_bounds``, the centre for a
    count of 1) inside ``[lower, upper]`` is among the evaluated points ``xs`` — i.e. the worst value of a partly
    evaluated grid (stopped at a breach) restricted to that box is exact."""
    expected = 1
    for (glo, ghi), n, lo, hi in zip(grid_bounds, counts, lower, upper, strict=True):
        nodes = np.full(1, (glo + ghi) / 2) if int(n) == 1 else np.linspace(glo, ghi, int(n))
        expected *= int(np.sum((nodes >= lo - 1e-9) & (nodes <= hi + 1e-9)))
    return int(_inside(np.asarray(xs, dtype=np.float64).reshape(-1, len(counts)), lower, upper).sum()) >= expected


def reference_rows(ref_rows: Iterable[JobRow], boxes: Sequence[BoxSpec], eps_safe_m: float,
                   penalty_m: float) -> list[JobRow]:
    """Pseudo-rows ``method=REFERENCE_METHOD`` giving, per image and per box of ``boxes``, the dense grid's worst
    value restricted to that box — the true worst case up to the grid spacing.

    ``ref_rows`` need their points (``store.jobs(role="reference", with_points=True)``); a box not inside a
    grid's box is skipped for that image. A grid stopped at a breach (centre-out) gives a row for a box only if
    the box holds an evaluated breach (its worst value is then a lower bound) or all its lattice nodes were
    evaluated (:func:`lattice_covered`). The pseudo-rows keep the grid's other fields (budget, nfev, timings).
    """
    out = []
    for r in ref_rows:
        if r.status is not JobStatus.DONE or r.points is None or r.box is None:
            continue
        grid = r.box.box
        for b in boxes:
            if b.box.names != grid.names:
                continue
            lo, hi = b.box.lower, b.box.upper
            if np.any(lo < grid.lower - 1e-9) or np.any(hi > grid.upper + 1e-9):
                continue
            w = worst_within(r.points.xs, r.points.fs, lo, hi, penalty_m)
            if math.isnan(w):
                continue
            if w <= eps_safe_m and not grid_complete(r):
                counts = r.options.get("counts")
                bounds = list(zip(grid.lower, grid.upper, strict=True))
                if counts is None or not lattice_covered(r.points.xs, bounds, counts, lo, hi):
                    continue
            inside = _inside(r.points.xs, lo, hi)
            pts = Points(r.points.xs[inside], r.points.fs[inside],
                         tuple(c for c, k in zip(r.points.reasons, inside, strict=True) if k))
            out.append(r.replace(method=REFERENCE_METHOD, box=b, worst_m=w, worst_x=None, points=pts, trace=(),
                                 verdict=Verdict.BREACH if w > eps_safe_m else Verdict.NO_BREACH_FOUND))
    return out


def against_reference(rows: Iterable[JobRow], ref_rows: Iterable[JobRow], eps_safe_m: float) -> list[dict[str, Any]]:
    """Per method, box and budget of ``rows``: its verdicts against the dense grid's (``ref_rows``, the pseudo-rows
    of :func:`reference_rows`) on the images both have — ``grid_breaches`` (images the grid breaks), ``found`` (of
    those, the ones the method breaks too), ``missed`` (the method survives where the grid breaks),
    ``beyond_grid`` (the method breaks an image the grid does not: a breach between grid nodes), ``found_pct`` and
    the exact McNemar ``p_value`` of method vs grid (:func:`vbl_robust.stats.paired`). Is the worst case really
    found?"""
    rows = list(rows)
    truth = {(r.box_label, r.sample_id): survived(r, eps_safe_m) for r in ref_rows}
    ok = {(r.method, r.box_label, r.budget_label, r.sample_id): survived(r, eps_safe_m) for r in rows}
    out = []
    for m, b, budget in dict.fromkeys((r.method, r.box_label, r.budget_label) for r in rows):
        ids = [sid for (mm, bb, bu, sid) in ok if (mm, bb, bu) == (m, b, budget) and (b, sid) in truth]
        if not ids:
            continue
        t = paired([truth[(b, i)] for i in ids], [ok[(m, b, budget, i)] for i in ids])
        breaches = t.neither + t.only_b
        out.append({"method": m, "box_label": b, "budget_label": budget, "n": t.n, "grid_breaches": breaches,
                    "found": t.neither, "missed": t.only_b, "beyond_grid": t.only_a,
                    "found_pct": 100.0 * t.neither / breaches if breaches else math.nan,
                    "p_value": t.p_value})
    return out


def grid_complete(r: JobRow) -> bool:
    """True if a grid job row evaluated its whole lattice (its evaluation budget is the lattice size)."""
    size = None if r.budget is None else r.budget.max_evals
    return size is not None and r.nfev >= size


def smallest_breach_levels(rows: Iterable[JobRow]) -> dict[tuple[str, str], float]:
    """Per (sample id, method): the smallest box level (roll half-width) at which a breach was found (a failed
    sample counts as breached at its smallest level), ``inf`` when none up to the largest level."""
    out: dict[tuple[str, str], float] = {}
    for r in rows:
        key = (r.sample_id, r.method)
        cur = out.setdefault(key, math.inf)
        if r.verdict in (Verdict.BREACH, Verdict.FAILED):
            out[key] = min(cur, float(r.box_level))
    return out


def survival_curve(levels: Sequence[float], budgets: Sequence[float]) -> list[float]:
    """Survival % at each budget b when image i first breaches at ``levels[i]`` (breached at b iff level ≤ b)."""
    lv = np.asarray(levels, dtype=np.float64)
    if lv.size == 0:
        return [math.nan for _ in budgets]
    return [float(100.0 * np.mean(lv > b)) for b in budgets]


def phi_crit(levels: Sequence[float], budgets: Sequence[float], threshold_pct: float = 10.0) -> float:
    """φ_crit: the smallest budget at which survival drops below ``threshold_pct`` %; ``inf`` when it never does
    within ``budgets`` (reported as "≥ the largest budget")."""
    for b, s in zip(budgets, survival_curve(levels, budgets), strict=True):
        if s < threshold_pct:
            return float(b)
    return math.inf


def quartile_edges(distances: Sequence[float], q: int = 4) -> np.ndarray:
    """``q + 1`` edges (metres) splitting slant distances into ``q`` groups of (nearly) equal size."""
    d = np.asarray(distances, dtype=np.float64)
    return np.quantile(d, np.linspace(0.0, 1.0, q + 1))


def quartile_of(distance: float, edges: np.ndarray) -> int:
    """Index (0 = closest) of the quartile ``distance`` falls in (the last edge belongs to the last quartile)."""
    return int(min(np.searchsorted(edges, distance, side="right") - 1, len(edges) - 2))


def distance_profile(rows: Iterable[JobRow], distances: dict[str, float], budgets: Sequence[float],
                     q: int = 4, threshold_pct: float = 10.0) -> list[dict[str, Any]]:
    """Per distance quartile and method: n, slant-distance range, median smallest breaching level, survival per
    budget and φ_crit (``inf`` = no drop below ``threshold_pct`` within the budgets)."""
    lv = smallest_breach_levels(rows)
    ids = sorted({sid for sid, _ in lv if sid in distances}, key=lambda s: distances[s])
    if not ids:
        return []
    edges = quartile_edges([distances[s] for s in ids], q)
    methods = list(dict.fromkeys(m for _, m in lv))
    out = []
    for k in range(q):
        members = [s for s in ids if quartile_of(distances[s], edges) == k]
        for m in methods:
            levels = [lv[(s, m)] for s in members if (s, m) in lv]
            finite = [v for v in levels if math.isfinite(v)]
            out.append({
                "quartile": k + 1, "d_min_m": float(edges[k]), "d_max_m": float(edges[k + 1]), "method": m,
                "n": len(levels), "median_level": float(np.median(levels)) if levels else math.nan,
                "n_breached": len(finite), "survival": survival_curve(levels, budgets),
                "phi_crit": phi_crit(levels, budgets, threshold_pct) if levels else math.nan,
            })
    return out


#: ``method`` of a family's combined series: an image breaches a level when some method (the grid included) found
#: a breach within it.
ANY_METHOD = "any method"
#: Survival thresholds (%) by which the families are ranked (:func:`rank_families`).
RANK_THRESHOLDS = (50.0, 10.0)


def family_of(row: JobRow) -> str | None:
    """The perturbation family of a row: the parameter of its 1-D box (None for other rows)."""
    if row.box is None or row.box.box.dim != 1:
        return None
    return row.box.box.names[0]


def first_level_below(levels: Sequence[float], survival: Sequence[float], threshold_pct: float) -> float:
    """The smallest level at which survival is below ``threshold_pct`` %; ``inf`` when it never is ("not
    reached"; NaN survivals, levels without rows, never count)."""
    for lv, s in sorted(zip(levels, survival, strict=True)):
        if s < threshold_pct:
            return float(lv)
    return math.inf


def family_profile(rows: Iterable[JobRow], eps_safe_m: float,
                   thresholds: Sequence[float] = RANK_THRESHOLDS) -> list[dict[str, Any]]:
    """Per perturbation family (:func:`family_of`) and method, over 1-D search rows (main rows and the reference
    pseudo-rows of :func:`reference_rows`): survival at each level, and the first level at which it drops below
    each threshold; plus, per family, the series :data:`ANY_METHOD` (an image breaches level b when some method
    breached at a level ≤ b, levels being nested).

    Each entry: ``family``, ``method``, ``levels`` (sorted box levels), ``labels`` (box labels), ``bounds`` (the
    ``(lower, upper)`` of each level), ``unit``, ``n`` (images per level), ``survival`` (% per level, as
    :func:`summarize` gives them; for :data:`ANY_METHOD` from :func:`smallest_breach_levels`) and, per threshold
    t, ``below_<t>`` (:func:`first_level_below`; ``inf`` = not reached). Families and methods keep first-seen
    order."""
    by_family: dict[str, list[JobRow]] = {}
    for r in rows:
        fam = family_of(r)
        if fam is not None:
            by_family.setdefault(fam, []).append(r)
    out: list[dict[str, Any]] = []
    for fam, rs in by_family.items():
        boxes = {r.box.level: r.box for r in sorted(rs, key=lambda r: r.box.level)}
        levels = sorted(boxes)
        base = {"family": fam, "levels": levels, "labels": [boxes[v].label for v in levels],
                "bounds": [(float(boxes[v].box.lower[0]), float(boxes[v].box.upper[0])) for v in levels],
                "unit": boxes[levels[0]].box.units[0]}
        for m in dict.fromkeys(r.method for r in rs):
            lines = {line.box_level: line for line in summarize([r for r in rs if r.method == m], eps_safe_m,
                                                                by=("box_level",))}
            surv = [lines[v].survival if v in lines else math.nan for v in levels]
            entry = {**base, "method": m, "n": [lines[v].n if v in lines else 0 for v in levels], "survival": surv}
            entry.update({f"below_{t:g}": first_level_below(levels, surv, t) for t in thresholds})
            out.append(entry)
        first: dict[str, float] = {}
        for (sid, _), lv in smallest_breach_levels(rs).items():
            first[sid] = min(first.get(sid, math.inf), lv)
        surv = survival_curve(list(first.values()), levels)
        entry = {**base, "method": ANY_METHOD, "n": [len(first)] * len(levels), "survival": surv}
        entry.update({f"below_{t:g}": first_level_below(levels, surv, t) for t in thresholds})
        out.append(entry)
    return out


def rank_families(profile: Sequence[Mapping[str, Any]], method: str = ANY_METHOD,
                  thresholds: Sequence[float] = RANK_THRESHOLDS) -> list[str]:
    """The families of ``profile`` (:func:`family_profile`), most vulnerable first: by the level at which the
    ``method`` series drops below each threshold in turn (not reached last), then by mean survival over the
    levels (lower first), then by name."""
    def key(p: Mapping[str, Any]) -> tuple:
        s = [v for v in p["survival"] if not math.isnan(v)]
        return (*(p[f"below_{t:g}"] for t in thresholds), float(np.mean(s)) if s else math.inf, p["family"])

    return [p["family"] for p in sorted((p for p in profile if p["method"] == method), key=key)]


def _or_nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


def convergence(rows: Iterable[JobRow], max_iter: int | None = None) -> list[dict[str, Any]]:
    """Per iteration k (1-based) over the rows' DIRECT-family traces: |PO_k| (as selected, and after the budget
    filter) and RA(k) in % — mean, standard deviation, 10/25/50/75/90th percentiles and maximum over images."""
    per_k: dict[int, dict[str, list[float]]] = {}
    for r in rows:
        for t in r.trace:
            if t.po_count_before is None:
                continue
            k = int(t.iteration)
            if max_iter is not None and k > max_iter:
                continue
            d = per_k.setdefault(k, {"po": [], "po_after": [], "ra": [], "best": [], "nfev": []})
            d["po"].append(float(t.po_count_before))
            d["po_after"].append(_or_nan(t.po_count_after))
            d["ra"].append(100.0 * _or_nan(t.remaining_area))
            d["best"].append(_or_nan(t.best_value))
            d["nfev"].append(float(t.nfev))
    out = []
    for k in sorted(per_k):
        d = per_k[k]
        line: dict[str, Any] = {"iteration": k, "n": len(d["po"])}
        for name in ("po", "ra"):
            v = np.asarray(d[name])
            line[f"{name}_mean"] = float(np.nanmean(v))
            line[f"{name}_std"] = float(np.nanstd(v))
            q = np.nanpercentile(v, [10, 25, 50, 75, 90])
            for label, x in zip(("q10", "q25", "median", "q75", "q90"), q, strict=True):
                line[f"{name}_{label}"] = float(x)
            line[f"{name}_max"] = float(np.nanmax(v))
        line["po_after_mean"] = float(np.nanmean(d["po_after"]))
        line["nfev_mean"] = float(np.mean(d["nfev"]))
        line["best_median"] = float(np.nanmedian(d["best"])) if np.isfinite(d["best"]).any() else math.nan
        out.append(line)
    return out


def pnp_summary(rows: Iterable[JobRow]) -> list[dict[str, Any]]:
    """Per (keypoint source, solver) over the PnP-comparison rows: n, failures, median and mean absolute error
    (MAE) of the position (m) and of the relative error (% of slant distance), over successful solves."""
    acc: dict[tuple[str, str], dict[str, list[float]]] = {}
    for r in rows:
        if r.status is not JobStatus.DONE or not r.payload:
            continue
        for src, solvers in r.payload["errors"].items():
            for solver, e in solvers.items():
                d = acc.setdefault((src, solver), {"abs": [], "rel": [], "fail": []})
                ok = e["abs_m"] is not None
                d["fail"].append(0.0 if ok else 1.0)
                if ok:
                    d["abs"].append(e["abs_m"])
                    d["rel"].append(e["rel_pct"])
    out = []
    for (src, solver), d in acc.items():
        a, rl = np.asarray(d["abs"]), np.asarray(d["rel"])
        out.append({
            "source": src, "solver": solver, "n": len(d["fail"]), "failures": int(sum(d["fail"])),
            "median_abs_m": float(np.median(a)) if a.size else math.nan, "mae_abs_m": float(np.mean(a)) if a.size else math.nan,
            "median_rel_pct": float(np.median(rl)) if rl.size else math.nan,
            "mae_rel_pct": float(np.mean(rl)) if rl.size else math.nan,
            "p95_rel_pct": float(np.percentile(rl, 95)) if rl.size else math.nan,
        })
    return out


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


def read_off(row: JobRow, budget: Budget, eps_safe_m: float, penalty_m: float) -> JobRow:
    """The row of ``budget`` (a time or an evaluation budget) read off the stored run ``row`` (with points): the
    best value and point, counts and trace of the evaluations within the budget; ``read_from`` = the run's
    budget label. A failed run gives a failed row for the budget."""
    from ..search import at_budget
    from .work import result_fields

    base = row.replace(budget=budget, key=f"{row.key}@{budget.label}", read_from=row.budget_label, payload=None)
    if row.status is not JobStatus.DONE:
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


def main_rows(store: Any, spec: Any, *, with_trace: bool = True) -> list[JobRow]:
    """The main search rows of a campaign as its tables and figures show them: stored rows with their points (the
    kind of each breach, :func:`breach_kind`), with every run that reads smaller budgets off its trace replaced by
    its read-off rows (:func:`read_off_rows`)."""
    reads = reads_trace(spec)
    rows = store.jobs(kind="search", role="main", with_points=True, with_trace=with_trace or reads)
    return read_off_rows(rows, spec.eps_safe_m, spec.penalty_m) if reads else rows
