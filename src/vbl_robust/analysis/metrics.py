"""The paper's metrics over store rows (:class:`~vbl_robust.store.rows.JobRow`): survival rate, median worst
error, φ_crit, |PO_k| and RA(k), failed evaluations per reason, PnP errors, the perturbation families' survival
per budget level and their ranking.

Conventions: a row's ``worst_m`` is the worst error the search found for that image (metres); a flagged failure
of the pipeline counts with the failure penalty (5000 m by default). An image *survives* a box when its worst error
is ≤ ε_safe: S_rate = 100 · #survivors / N (%), N the images measured: a job the tool could not complete (not
measured) is in no rate, counted apart.

Budgets read off a trace: a stored run whose budget reads smaller budgets (``Budget.reads``, the runtime
experiments' anytime methods) stands for one result per read budget; :func:`.readoff.read_off_rows` derives those
rows (``JobRow.read_from`` = the run's budget label) from the run's stamped evaluations
(:func:`vbl_robust.search.anytime.at_budget`): at a time budget t only the evaluations completed by t count.

The metrics live in modules by concern, each imported from the module that defines it: per-job facts
(:mod:`.breach`), summaries (:mod:`.summary`), the grid reference (:mod:`.reference`), breach levels and families
(:mod:`.levels`) and budgets read off a trace (:mod:`.readoff`); the convergence of DIRECT-family traces and the
PnP comparison are here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..specs.kinds import JobStatus
from ..store.rows import JobRow

__all__ = ["ConvergenceLine", "PnpLine", "convergence", "pnp_summary"]


def _or_nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


@dataclass(frozen=True)
class ConvergenceLine:
    """One iteration k (1-based) over ``n`` images' DIRECT-family traces: |PO_k| as selected (``po_*``) and RA(k) in %
    (``ra_*``) — mean, standard deviation, 10/25/50/75/90th percentiles and maximum over images —, the mean |PO_k|
    after the budget filter, the mean evaluations so far and the median best value (m; NaN: none finite)."""

    iteration: int
    n: int
    po_mean: float
    po_std: float
    po_q10: float
    po_q25: float
    po_median: float
    po_q75: float
    po_q90: float
    po_max: float
    ra_mean: float
    ra_std: float
    ra_q10: float
    ra_q25: float
    ra_median: float
    ra_q75: float
    ra_q90: float
    ra_max: float
    po_after_mean: float
    nfev_mean: float
    best_median: float


def _spread(v: list[float]) -> list[float]:
    """Mean, standard deviation, 10/25/50/75/90th percentiles and maximum (NaN ignored)."""
    a = np.asarray(v)
    return [float(np.nanmean(a)), float(np.nanstd(a)), *map(float, np.nanpercentile(a, [10, 25, 50, 75, 90])),
            float(np.nanmax(a))]


def convergence(rows: Iterable[JobRow], max_iter: int | None = None) -> list[ConvergenceLine]:
    """Per iteration k (1-based) over the rows' DIRECT-family traces, a :class:`ConvergenceLine`."""
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
    return [ConvergenceLine(k, len(d["po"]), *_spread(d["po"]), *_spread(d["ra"]), float(np.nanmean(d["po_after"])),
                            float(np.mean(d["nfev"])),
                            float(np.nanmedian(d["best"])) if np.isfinite(d["best"]).any() else math.nan)
            for k, d in sorted(per_k.items())]


@dataclass(frozen=True)
class PnpLine:
    """One (keypoint ``source``, ``solver``) over the PnP-comparison rows: ``n`` images, ``failures``, the median and
    mean absolute error (MAE) of the position (m) and of the relative error (% of slant distance), and the 95th
    percentile of the relative error, over successful solves (NaN: none)."""

    source: str
    solver: str
    n: int
    failures: int
    median_abs_m: float
    mae_abs_m: float
    median_rel_pct: float
    mae_rel_pct: float
    p95_rel_pct: float


def pnp_summary(rows: Iterable[JobRow]) -> list[PnpLine]:
    """Per (keypoint source, solver) over the PnP-comparison rows, a :class:`PnpLine`."""
    acc: dict[tuple[str, str], dict[str, list[float]]] = {}
    for r in rows:
        if r.status != JobStatus.DONE or not r.payload:
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
        out.append(PnpLine(
            src, solver, len(d["fail"]), int(sum(d["fail"])),
            float(np.median(a)) if a.size else math.nan, float(np.mean(a)) if a.size else math.nan,
            float(np.median(rl)) if rl.size else math.nan, float(np.mean(rl)) if rl.size else math.nan,
            float(np.percentile(rl, 95)) if rl.size else math.nan))
    return out
