"""The dense grid as the reference: its worst value restricted to each nested box (:func:`reference_rows`) and
every method's verdicts against it (:func:`against_reference`). Re-exported by
:mod:`vbl_robust.analysis.metrics`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from ..constants import Verdict
from ..specs.campaign import BoxSpec
from ..specs.kinds import JobStatus
from ..stats import paired
from ..store.rows import JobRow, Points, StoredPoints
from .breach import survived

#: ``method`` of the pseudo-rows of :func:`reference_rows`.
REFERENCE_METHOD = "grid (reference)"

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
        if r.status != JobStatus.DONE or r.points is None or r.box is None:
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
            # a grid read on demand (a large store) is restricted on demand too: nothing held per box
            pts = (StoredPoints(partial(_restricted, r.points, lo, hi)) if isinstance(r.points, StoredPoints)
                   else _restricted(r.points, lo, hi))
            out.append(r.replace(method=REFERENCE_METHOD, box=b, worst_m=w, worst_x=None, points=pts, trace=(),
                                 verdict=Verdict.BREACH if w > eps_safe_m else Verdict.NO_BREACH_FOUND))
    return out


def _restricted(points: Points, lower: Sequence[float], upper: Sequence[float], raw: bool = False) -> Any:
    """The points of ``points`` inside the box ``[lower, upper]`` (``raw``: as stored bytes)."""
    inside = _inside(points.xs, lower, upper)
    out = Points(points.xs[inside], points.fs[inside], tuple(c for c, k in zip(points.reasons, inside, strict=True) if k))
    return out.to_blob() if raw else out


@dataclass(frozen=True)
class AgainstGrid:
    """A method's verdicts at one box and budget against the dense grid's, on the ``n`` images both have:
    ``grid_breaches`` (images the grid breaks), ``found`` (of those, the ones the method breaks too), ``missed``
    (the method survives where the grid breaks), ``beyond_grid`` (the method breaks an image the grid does not: a
    breach between grid nodes), ``found_pct`` (NaN: the grid breaks none) and the exact McNemar ``p_value`` of
    method vs grid (:func:`vbl_robust.stats.paired`)."""

    method: str
    box_label: str | None
    budget_label: str | None
    n: int
    grid_breaches: int
    found: int
    missed: int
    beyond_grid: int
    found_pct: float
    p_value: float


def against_reference(rows: Iterable[JobRow], ref_rows: Iterable[JobRow], eps_safe_m: float) -> list[AgainstGrid]:
    """Per method, box and budget of ``rows``: its :class:`AgainstGrid` verdicts against the dense grid's
    (``ref_rows``, the pseudo-rows of :func:`reference_rows`). Is the worst case really found?"""
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
        out.append(AgainstGrid(m, b, budget, t.n, breaches, t.neither, t.only_b, t.only_a,
                               100.0 * t.neither / breaches if breaches else math.nan, t.p_value))
    return out


def grid_complete(r: JobRow) -> bool:
    """True if a grid job row evaluated its whole lattice (its evaluation budget is the lattice size)."""
    size = None if r.budget is None else r.budget.max_evals
    return size is not None and r.nfev >= size
