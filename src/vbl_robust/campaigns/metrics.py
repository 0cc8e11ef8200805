"""The paper's metrics over store rows (:class:`~vbl_robust.campaigns.store.JobRow`): survival rate, median worst
error, φ_crit, |PO_k| and RA(k), failed evaluations per reason, PnP errors, the perturbation families' survival
per budget level and their ranking.

Conventions: a row's ``worst_m`` is the worst error the search found for that image (metres); a flagged failure
of the pipeline counts with the failure penalty (5000 m by default). An image *survives* a box when its worst error
is ≤ ε_safe: S_rate = 100 · #survivors / N (%), N the images measured: a job the tool could not complete (not
measured) is in no rate, counted apart.

Budgets read off a trace: a stored run whose budget reads smaller budgets (``Budget.reads``, the runtime
experiments' anytime methods) stands for one result per read budget; :func:`read_off_rows` derives those rows
(``JobRow.read_from`` = the run's budget label) from the run's stamped evaluations
(:func:`vbl_robust.search.at_budget`): at a time budget t only the evaluations completed by t count.

The metrics live in modules by concern and are all importable from here: per-job facts (:mod:`.breach`),
summaries (:mod:`.summary`), the grid reference (:mod:`.reference`), breach levels and families (:mod:`.levels`)
and budgets read off a trace (:mod:`.readoff`); the convergence of DIRECT-family traces and the PnP comparison
are here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from .breach import (
    breach_kind,
    breached_images,
    budget_value,
    empty_row,
    failure_counts,
    measured_rows,
    not_measured_lines,
    residual_bound,
    survival_rate,
    survived,
)
from .levels import (
    ANY_METHOD,
    RANK_THRESHOLDS,
    distance_profile,
    family_of,
    family_profile,
    first_level_below,
    phi_crit,
    quartile_edges,
    quartile_of,
    rank_families,
    smallest_breach_levels,
    survival_curve,
)
from .readoff import main_rows, read_off, read_off_rows, reads_trace, row_result
from .reference import (
    REFERENCE_METHOD,
    against_reference,
    grid_complete,
    lattice_covered,
    reference_rows,
    worst_within,
)
from .store import JobRow, JobStatus
from .summary import GROUP_BY, Summary, columns, summarize

__all__ = [
    "ANY_METHOD", "GROUP_BY", "RANK_THRESHOLDS", "REFERENCE_METHOD", "Summary", "against_reference", "breach_kind",
    "breached_images", "budget_value", "columns", "convergence", "distance_profile", "empty_row", "failure_counts",
    "family_of", "family_profile", "first_level_below", "grid_complete", "lattice_covered", "main_rows",
    "measured_rows", "not_measured_lines",
    "phi_crit", "pnp_summary", "quartile_edges", "quartile_of", "rank_families", "read_off", "read_off_rows",
    "reads_trace", "reference_rows", "residual_bound", "row_result", "smallest_breach_levels", "summarize",
    "survival_curve", "survival_rate", "survived", "worst_within",
]


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
