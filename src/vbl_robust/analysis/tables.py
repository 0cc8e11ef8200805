"""Flat exports of a store: its job rows (CSV, standard library; Parquet, pyarrow) and its summary table.

:func:`export` writes one line per job with the identifying columns, the worst error and point (one column per
parameter, real units), verdict, the detector that was audited (name, SHA-256, design: single pass or two-stage,
input size, engine), the kind of breach (``breach_kind``: safe / flagged / misleading) and what "no
breach found" is worth for a uniform random search (``residual_bound``), the image's unperturbed error L(0)
(``nominal_m``, from main jobs stored with it; empty in older stores), counts and timings (a sequence campaign's main jobs also their breach facts along the approach,
:data:`SEQUENCE_COLUMNS`); traces, evaluated points and per-frame errors stay in the store. A run that reads smaller
budgets off its trace (runtime experiments) is followed by one line per read budget, derived from it
(:func:`~vbl_robust.analysis.readoff.read_off_rows`; column ``read_from`` = the run's budget label).

:func:`summary_records` gives the summary table (``vbl-robust report RUN --format csv|json``): one record per
method, box and budget with the survival rate and its exact 95 % interval (:data:`SUMMARY_COLUMNS`).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from enum import Enum
from pathlib import Path
from typing import Any

from ..specs.kinds import JobKind, Role
from ..store.core import ResultStore
from ..store.payloads import RiskPayload, SequencePayload, WorstPayload
from ..store.rows import JobRow

COLUMNS = (
    "experiment", "kind", "role", "method", "sample_id", "sample_index", "slant_distance_m", "envelope", "box_label",
    "box_level", "budget_label", "max_evals", "max_seconds", "max_iters", "stop_at_breach", "seed", "status",
    "reason", "worst_m", "verdict", "nfev", "nit", "n_failed", "failures", "worst_reason", "search_status",
    "search_s", "job_s", "upper_bound", "bound_estimate", "run_id", "key", "read_from", "breach_kind",
    "residual_bound", "detector", "detector_sha256", "design", "input_size", "engine", "nominal_m",
)
#: The detector columns of every job line (the campaign's detector identity): which pipeline was audited.
DETECTOR_COLUMNS = {"detector": "name", "detector_sha256": "sha256", "design": "design", "input_size": "input_size",
                    "engine": "engine"}
#: Columns of a risk job (``vbl-robust risk``; fractions): the failure probability, its interval, the verdict on
#: p_fail ≤ τ and the evaluations spent.
RISK_COLUMNS = ("p_fail", "ci_low", "ci_high", "ci_level", "tau", "risk_verdict", "evaluations")

#: Columns of :func:`summary_records` (survival in %, its exact 95 % interval; ``residual_bound``: for random
#: search, the largest bound on the breached fraction of the box over the images without a breach).
SUMMARY_COLUMNS = (
    "experiment", "method", "box_label", "box_level", "budget_label", "images", "survivors", "survival_pct",
    "survival_ci_low", "survival_ci_high", "breaches", "misleading", "flagged", "certified", "not_measured",
    "median_worst_m", "mean_evals", "residual_bound",
)


#: Columns of a sequence campaign's main jobs (after the parameters): the breach facts of the worst θ and the
#: unperturbed θ's sustained error, from the job's ``sequence`` payload (:func:`vbl_robust.campaigns.work.sequence_details`).
SEQUENCE_COLUMNS = ("longest_run_frames", "longest_run_s", "breached_frames", "failed_frames", "breach_start_m",
                    "breach_start_frame", "first_breach_m", "nominal_sustained_m", "nominal_breached_frames")


def _plain(v: Any) -> Any:
    if isinstance(v, Enum):
        return v.value
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True) if v else None
    return v


class FlatRows:
    """A store's job rows as flat dicts, read from the store one at a time (a reader of every row holds one): iterate
    it for the dicts; :attr:`columns` after a whole iteration gives their column names (``COLUMNS``, then the
    ``worst_<parameter>`` columns met, then a sequence's or a risk run's columns when some row had them).
    ``failures`` is the JSON ``{reason: count}`` of the failed evaluations; a run that reads budgets off its trace
    is followed by one line per read budget (the main rows only)."""

    def __init__(self, store: ResultStore):
        from ..constants import EPS_SAFE_M

        self.store = store
        self.samples = store.samples()
        camp = store.require_campaign() if store.holds_campaign() else None
        self.eps, self.penalty = ((camp.stored_spec.get("eps_safe_m"), camp.stored_spec.get("penalty_m")) if camp
                                  else (None, None))
        self.eps_kind = EPS_SAFE_M if self.eps is None else self.eps
        ident = (camp.detector if camp else None) or {}
        self.detector = {col: ident.get(key) for col, key in DETECTOR_COLUMNS.items()}
        self.params: list[str] = []
        self.sequences = self.has_risk = False

    @property
    def columns(self) -> list[str]:
        return [*COLUMNS, *self.params, *(SEQUENCE_COLUMNS if self.sequences else ()),
                *(RISK_COLUMNS if self.has_risk else ())]

    def _rows(self, reads: bool) -> Iterator[JobRow]:
        """Every stored row with its points (and the read-off rows after their run's, when ``reads``)."""
        from .readoff import read_off

        for r in self.store.iter_jobs(with_trace=reads, with_points=True):
            yield r
            if reads and r.role == Role.MAIN and r.budget is not None and r.budget.reads:
                yield from (read_off(r, b, self.eps, self.penalty) for b in r.budget.read_budgets())

    def __iter__(self) -> Iterator[dict[str, Any]]:
        from .breach import breach_kind, residual_bound

        reads, nominal = False, {}
        for r in self.store.iter_jobs(with_trace=False):  # a first pass: L(0), the image's whatever the job
            reads |= r.budget is not None and r.budget.reads
            if (p := WorstPayload.of(r)) is not None and p.nominal:
                nominal[r.sample_id] = p.nominal.error_m
        self.params, self.sequences, self.has_risk = [], False, False
        for r in self._rows(reads):
            s = self.samples.get(r.sample_id)
            b = {} if r.budget is None else r.budget.to_dict()
            d = {c: _plain(getattr(r, c, None)) for c in COLUMNS}
            d.update(self.detector)
            d["nominal_m"] = nominal.get(r.sample_id)
            d.update(slant_distance_m=None if s is None else s.slant_distance_m,
                     envelope=None if s is None else s.envelope, max_evals=b.get("max_evals"),
                     max_seconds=b.get("max_seconds"), max_iters=b.get("max_iters"),
                     stop_at_breach=b.get("stop_at_breach"))
            risk = RiskPayload.of(r) if r.kind == JobKind.RISK else None
            if risk is not None:
                self.has_risk = True
                d.update({c: getattr(risk, c) for c in RISK_COLUMNS if c != "risk_verdict"}, risk_verdict=risk.verdict)
            if r.kind == JobKind.SEARCH and r.measured:
                kind = breach_kind(r, self.eps_kind)
                d.update(breach_kind=None if kind is None else kind.value, residual_bound=residual_bound(r, self.eps_kind))
            for name, v in (r.worst_x or {}).items():
                col = f"worst_{name}"
                if col not in self.params:
                    self.params.append(col)
                d[col] = v
            seq = None if r.read_from else SequencePayload.of(r)
            if seq is not None:
                self.sequences = True
                d.update({c: getattr(seq.worst, c) for c in SEQUENCE_COLUMNS[:7]},
                         nominal_sustained_m=seq.nominal.sustained_m,
                         nominal_breached_frames=seq.nominal.breached_frames)
            yield d


def flat_rows(store: ResultStore) -> tuple[list[dict[str, Any]], list[str]]:
    """Every job row as a flat dict (:class:`FlatRows`), and their column names."""
    flat = FlatRows(store)
    rows = list(flat)
    return rows, flat.columns


def summary_records(store: ResultStore) -> list[dict[str, Any]]:
    """The run's summary table: one record per method, box and budget of its main search rows (and of the dense
    grid's reference pseudo-rows, method ``grid (reference)``), :data:`SUMMARY_COLUMNS` each; ``ValueError`` for a
    store without a campaign."""
    import math

    from .readoff import main_rows
    from .reference import reference_rows
    from .summary import summarize

    spec = store.spec()
    rows = main_rows(store, spec, with_trace=False, measured_only=False)  # counted apart (not_measured)
    boxes = list({r.box.label: r.box for r in rows if r.box is not None}.values())
    ref = store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
    rows += reference_rows(ref, boxes, spec.settings.eps_safe_m, spec.settings.penalty_m)
    out = []
    for s in summarize(rows, spec.settings.eps_safe_m):
        ci = s.survival_rate.ci if s.measured else None
        out.append({
            "experiment": spec.name, "method": s.method, "box_label": s.box_label, "box_level": s.box_level,
            "budget_label": s.budget_label, "images": s.n, "survivors": s.survivors,
            "survival_pct": s.survival if s.measured else None, "survival_ci_low": ci and ci.low, "survival_ci_high": ci and ci.high, "breaches": s.breaches,
            "misleading": s.misleading, "flagged": s.flagged, "certified": s.certified, "not_measured": s.not_measured,
            "median_worst_m": None if math.isnan(s.median_worst_m) else s.median_worst_m,
            "mean_evals": s.mean_nfev if s.measured else None, "residual_bound": s.residual,
        })
    return out


#: Columns of a risk run's summary (:func:`risk_records`): per estimator, the failure probability pooled over the
#: images (a fraction) with its interval at ``ci_level``, the verdicts on p_fail ≤ ``tau`` per image, evaluations.
RISK_SUMMARY_COLUMNS = (
    "experiment", "method", "box_label", "images", "p_fail", "p_fail_ci_low", "p_fail_ci_high", "ci_level", "tau",
    "holds", "violated", "undecided", "not_measured", "evaluations",
)


def risk_records(store: ResultStore) -> list[dict[str, Any]]:
    """A risk run's summary (:func:`vbl_robust.risk.pooled_risk` per estimator), one record of
    :data:`RISK_SUMMARY_COLUMNS` per estimator; none for a run without risk rows."""
    from .risk import pooled_risk

    camp = store.require_campaign()
    rows = store.jobs(kind="risk", with_points=True, with_trace=False)
    boxes = {r.method: r.box_label for r in rows}
    unmeasured: dict[str, int] = {}
    for r in rows:
        unmeasured[r.method] = unmeasured.get(r.method, 0) + (not r.measured)
    out = [{"experiment": camp.name, "method": p.method, "box_label": boxes.get(p.method), "images": p.images,
            "p_fail": p.p_fail, "p_fail_ci_low": p.ci.low, "p_fail_ci_high": p.ci.high, "ci_level": p.ci.level,
            "tau": p.tau, "holds": p.holds, "violated": p.violated, "undecided": p.undecided,
            "not_measured": unmeasured.pop(p.method, 0), "evaluations": p.evaluations} for p in pooled_risk(rows)]
    out += [{"experiment": camp.name, "method": m, "box_label": boxes.get(m), "images": 0, "not_measured": k}
            for m, k in unmeasured.items()]  # an estimator whose every job was not measured
    return out


def summary_table(store: ResultStore) -> tuple[list[dict[str, Any]], tuple[str, ...]]:
    """What ``report --format csv|json`` prints: the records and their columns — a risk run's per-estimator
    failure probability (:func:`risk_records`), any other run's survival table (:func:`summary_records`)."""
    if any(blk.kind == JobKind.RISK for blk in store.spec().blocks):
        return risk_records(store), RISK_SUMMARY_COLUMNS
    return summary_records(store), SUMMARY_COLUMNS


def write_records(records: list[dict[str, Any]], columns: tuple[str, ...], fmt: str, stream: Any) -> None:
    """``records`` to ``stream`` as ``csv`` (a header, then one line each) or ``json`` (a list of objects)."""
    if fmt == "csv":
        w = csv.DictWriter(stream, fieldnames=list(columns), extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        w.writerows(records)
    elif fmt == "json":
        stream.write(json.dumps([{c: r.get(c) for c in columns} for r in records], indent=1) + "\n")
    else:
        raise ValueError(f"format must be csv or json, got {fmt!r}")


def export(store: ResultStore, path: str | Path) -> Path:
    """Write the job rows to ``path``: ``.csv`` or ``.parquet`` (by suffix; ``ValueError`` otherwise)."""
    p = Path(path)
    if p.suffix.lower() not in (".csv", ".parquet"):
        raise ValueError(f"export {p}: unknown format (use a .csv or .parquet file name)")
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.suffix.lower() == ".csv":  # the header names every column: the rows are read first
        rows, cols = flat_rows(store)
        with open(p, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
        return p
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(_arrow_table(FlatRows(store)), p)
    pa.default_memory_pool().release_unused()  # Arrow's allocator keeps what it freed: given back (what follows, a
    return p                                   # bundle's report, needs it more)


#: Rows per Arrow batch of :func:`_arrow_table`.
BATCH_ROWS = 4096


def _arrow_table(flat: FlatRows) -> Any:
    """The rows of ``flat`` as one Arrow table of its columns, built a batch of :data:`BATCH_ROWS` rows at a time
    (the columns of a large store's rows, not a dict per row, are what is held): each column's type is what Arrow
    infers from all its values, as from one list (a column without a value in one batch takes the others' type)."""
    import pyarrow as pa

    def table(batch: list[dict[str, Any]]) -> Any:  # the columns met so far; a later one is null here when joined
        return pa.table({c: [r.get(c) for r in batch] for c in flat.columns})

    batches, batch = [], []
    for d in flat:
        batch.append(d)
        if len(batch) == BATCH_ROWS:
            batches.append(table(batch))
            batch = []
    if batch or not batches:
        batches.append(table(batch))
    return pa.concat_tables(batches, promote_options="permissive").select(flat.columns)
