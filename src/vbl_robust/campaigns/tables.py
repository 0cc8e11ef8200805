"""Flat exports of a store's job rows: CSV (standard library) and Parquet (pyarrow).

One line per job with the identifying columns, the worst error and point (one column per parameter, real
units), verdict, counts and timings (a sequence campaign's main jobs also their breach facts along the approach,
:data:`SEQUENCE_COLUMNS`); traces, evaluated points and per-frame errors stay in the store. A run that reads smaller
budgets off its trace (runtime experiments) is followed by one line per read budget, derived from it
(:func:`~vbl_robust.campaigns.metrics.read_off_rows`; column ``read_from`` = the run's budget label).
"""

from __future__ import annotations

import csv
import json
from enum import Enum
from pathlib import Path
from typing import Any

from .store import ResultStore

COLUMNS = (
    "experiment", "kind", "role", "method", "sample_id", "sample_index", "slant_distance_m", "envelope", "box_label",
    "box_level", "budget_label", "max_evals", "max_seconds", "max_iters", "stop_at_breach", "seed", "status",
    "reason", "worst_m", "verdict", "nfev", "nit", "n_failed", "failures", "worst_reason", "search_status",
    "search_s", "job_s", "upper_bound", "bound_estimate", "run_id", "key", "read_from",
)


#: Columns of a sequence campaign's main jobs (after the parameters): the breach facts of the worst θ and the
#: unperturbed θ's sustained error, from the job's ``sequence`` payload (:func:`.work.sequence_details`).
SEQUENCE_COLUMNS = ("longest_run_frames", "longest_run_s", "breached_frames", "failed_frames", "breach_start_m",
                    "breach_start_frame", "first_breach_m", "nominal_sustained_m", "nominal_breached_frames")


def _plain(v: Any) -> Any:
    if isinstance(v, Enum):
        return v.value
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True) if v else None
    return v


def flat_rows(store: ResultStore) -> tuple[list[dict[str, Any]], list[str]]:
    """Job rows as flat dicts, and the column names (``COLUMNS`` then ``worst_<parameter>`` columns);
    ``failures`` is the JSON ``{reason: count}`` of the failed evaluations."""
    from .metrics import read_off

    samples = store.samples()
    camp = store.campaign()
    eps, penalty = ((camp["spec"].get("eps_safe_m"), camp["spec"].get("penalty_m")) if camp else (None, None))
    stored = store.jobs(with_trace=False)
    if any(r.budget is not None and r.budget.reads for r in stored):
        full = {r.key: r for r in store.jobs(role="main", with_points=True) if r.budget is not None and r.budget.reads}
        stored = [x for r in stored for x in
                  ([r] + ([read_off(full[r.key], b, eps, penalty) for b in r.budget.read_budgets()]
                          if r.key in full else []))]
    rows, params, sequences = [], [], False
    for r in stored:
        s = samples.get(r.sample_id, {})
        b = {} if r.budget is None else r.budget.to_dict()
        d = {c: _plain(getattr(r, c, None)) for c in COLUMNS}
        d.update(slant_distance_m=s.get("slant_distance_m"), envelope=s.get("envelope"), max_evals=b.get("max_evals"),
                 max_seconds=b.get("max_seconds"), max_iters=b.get("max_iters"), stop_at_breach=b.get("stop_at_breach"))
        for name, v in (r.worst_x or {}).items():
            col = f"worst_{name}"
            if col not in params:
                params.append(col)
            d[col] = v
        seq = None if r.read_from else (r.payload or {}).get("sequence")
        if seq is not None:
            sequences = True
            d.update({c: seq["worst"].get(c) for c in SEQUENCE_COLUMNS[:7]},
                     nominal_sustained_m=seq["nominal"].get("sustained_m"),
                     nominal_breached_frames=seq["nominal"].get("breached_frames"))
        rows.append(d)
    return rows, [*COLUMNS, *params, *(SEQUENCE_COLUMNS if sequences else ())]


def export(store: ResultStore, path: str | Path) -> Path:
    """Write the job rows to ``path``: ``.csv`` or ``.parquet`` (by suffix; ``ValueError`` otherwise)."""
    p = Path(path)
    rows, cols = flat_rows(store)
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.suffix.lower() == ".csv":
        with open(p, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
    elif p.suffix.lower() == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({c: [r.get(c) for r in rows] for c in cols})
        pq.write_table(table, p)
    else:
        raise ValueError(f"export {p}: unknown format (use a .csv or .parquet file name)")
    return p
