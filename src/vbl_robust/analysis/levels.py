"""Breach levels over nested boxes: the smallest level at which each image breaches, survival curves and φ_crit,
the profile per slant-distance quartile, and the perturbation families' survival per level and their ranking.
Re-exported by :mod:`vbl_robust.analysis.metrics`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constants import Verdict
from ..store.rows import JobRow
from .summary import summarize


def smallest_breach_levels(rows: Iterable[JobRow]) -> dict[tuple[str, str], float]:
    """Per (sample id, method): the smallest box level (roll half-width) at which a breach was found (a failed
    sample's rows not measured are left out), ``inf`` when none up to the largest level."""
    out: dict[tuple[str, str], float] = {}
    for r in rows:
        if not r.measured:
            continue
        key = (r.sample_id, r.method)
        cur = out.setdefault(key, math.inf)
        if r.verdict == Verdict.BREACH:
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


@dataclass(frozen=True)
class DistanceLine:
    """One slant-distance quartile (1 = closest) and method: its range ``d_min_m``–``d_max_m`` (m), ``n`` images, the
    median smallest breaching level, how many breached within the budgets, the survival % per budget and φ_crit
    (``inf`` = no drop below the threshold within the budgets; NaN without images)."""

    quartile: int
    d_min_m: float
    d_max_m: float
    method: str
    n: int
    median_level: float
    n_breached: int
    survival: list[float]
    phi_crit: float


def distance_profile(rows: Iterable[JobRow], distances: dict[str, float], budgets: Sequence[float],
                     q: int = 4, threshold_pct: float = 10.0) -> list[DistanceLine]:
    """Per distance quartile and method a :class:`DistanceLine` (φ_crit: the first budget at which survival drops
    below ``threshold_pct``)."""
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
            out.append(DistanceLine(k + 1, float(edges[k]), float(edges[k + 1]), m, len(levels),
                                    float(np.median(levels)) if levels else math.nan, len(finite),
                                    survival_curve(levels, budgets),
                                    phi_crit(levels, budgets, threshold_pct) if levels else math.nan))
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
