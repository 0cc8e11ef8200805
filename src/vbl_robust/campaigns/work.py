"""What a worker does: run the jobs of one sample and turn each outcome into a store row.

The unit of work is a :class:`SampleTask` (one sample + its pending jobs): the objective is built once per
(sample, box) and the detector once per process (:func:`detector_for`), never per job. :func:`run_sample_task`
yields, job after job, the rows to commit together (usually one; a breach in a chain brings the implied rows
of the larger boxes with it, so a chain is never half-recorded).

A sample the pipeline cannot process (unreadable image, an exception while building or evaluating the
objective) gives a row with status "failed", its reason, worst error = the failure penalty and verdict
"failed"; the campaign goes on.
"""

from __future__ import annotations

import json
import logging
import math
import time
import traceback
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .provenance import DetectorSpec
from .spec import Job
from .store import encode_points, now_iso

logger = logging.getLogger(__name__)

VERDICT_BREACH = "breach"
VERDICT_NONE = "no breach found"
VERDICT_CERTIFIED = "certified"
VERDICT_FAILED = "failed"

_DETECTORS: dict[str, Any] = {}


def detector_for(spec: DetectorSpec) -> Any:
    """The detector of ``spec``, built once per process (a model is loaded once, not per job)."""
    key = json.dumps(spec.to_dict(), sort_keys=True)
    if key not in _DETECTORS:
        _DETECTORS[key] = spec.build()
    return _DETECTORS[key]


@dataclass
class Settings:
    """Pipeline settings shared by all jobs of a campaign (see :class:`~vbl_robust.campaigns.spec.CampaignSpec`)."""

    eps_safe_m: float
    penalty_m: float
    conf_threshold: float
    pnp: str
    lipschitz: float | tuple[float, ...] | None = None

    @classmethod
    def from_spec(cls, spec: Any) -> Settings:
        return cls(spec.eps_safe_m, spec.penalty_m, spec.conf_threshold, spec.pnp, spec.lipschitz)


@dataclass
class SampleTask:
    """One sample and its pending jobs (in campaign order)."""

    sample: Any
    jobs: Sequence[Job]


def verdict(worst: float, upper_bound: float | None, eps: float) -> str:
    """breach (worst > ε) / certified (a sound upper bound ≤ ε) / no breach found."""
    if math.isfinite(worst) and worst > eps:
        return VERDICT_BREACH
    if upper_bound is not None and math.isfinite(upper_bound) and upper_bound <= eps:
        return VERDICT_CERTIFIED
    return VERDICT_NONE


def _base_row(job: Job, run_id: int | None) -> dict[str, Any]:
    return {
        "key": job.key, "run_id": run_id, "experiment": job.experiment, "kind": job.kind, "role": job.role,
        "method": job.method, "sample_id": job.sample_id, "sample_index": job.sample_index,
        "box_label": None if job.box is None else job.box.label,
        "box_level": None if job.box is None else job.box.level,
        "box_json": None if job.box is None else json.dumps(job.box.to_dict()),
        "budget_label": None if job.budget is None else job.budget.label,
        "budget_json": None if job.budget is None else json.dumps(job.budget.to_dict()),
        "seed": job.seed, "options_json": json.dumps(dict(job.options)), "chain": job.chain,
        "finished_at": now_iso(),
    }


def failed_row(job: Job, reason: str, settings: Settings, run_id: int | None = None, job_s: float = 0.0) -> dict[str, Any]:
    row = _base_row(job, run_id)
    row.update(status="failed", reason=reason, worst_m=settings.penalty_m, verdict=VERDICT_FAILED, nfev=0, nit=0,
               job_s=job_s)
    return row


def _finite(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def search_row(job: Job, result: Any, settings: Settings, run_id: int | None, job_s: float) -> dict[str, Any]:
    """Row of a finished search (a :class:`~vbl_robust.search.SearchResult`)."""
    row = _base_row(job, run_id)
    worst = float(result.fun) if math.isfinite(result.fun) else settings.penalty_m
    ub = getattr(result, "upper_bound", None)
    row.update(
        status="done", reason=None, worst_m=worst,
        worst_x_json=None if result.x is None else json.dumps(result.x_dict()),
        verdict=verdict(worst, ub, settings.eps_safe_m), nfev=int(result.nfev), nit=int(result.nit),
        search_status=result.status.value, message=result.message, search_s=float(result.elapsed), job_s=job_s,
        upper_bound=None if ub is None else (float(ub) if math.isfinite(ub) else 1e300),
        bound_estimate=_finite(getattr(result, "bound_estimate", None)),
        lipschitz_estimate=_finite(getattr(result, "lipschitz_estimate", None)),
        trace_json=json.dumps([r.to_dict() for r in result.trace]),
        points=encode_points(result.xs, result.fs),
    )
    return row


def implied_row(job: Job, breach_row: Mapping[str, Any], settings: Settings, run_id: int | None) -> dict[str, Any]:
    """A larger box of a chain after a breach at a smaller, nested box: the same breach point lies in it."""
    row = _base_row(job, run_id)
    row.update(status="implied", reason=f"breach found at {breach_row['box_label']}", worst_m=breach_row["worst_m"],
               worst_x_json=breach_row.get("worst_x_json"), verdict=VERDICT_BREACH, nfev=0, nit=0, search_s=0.0,
               job_s=0.0)
    return row


def worst_details(objective: Any, x: np.ndarray) -> dict[str, Any]:
    """What happened at the worst point (one more evaluation): failure reason ("" = a wrong pose, not a
    detection failure), top confidence, position error and estimated position."""
    rec = objective.evaluate(np.asarray(x, dtype=np.float64)[None])
    conf = float(rec.conf[0])
    err = float(rec.error_m[0])
    return {"reason": rec.reason[0], "conf": conf if math.isfinite(conf) else None,
            "error_m": err if math.isfinite(err) else None,
            "position": [float(v) if math.isfinite(v) else None for v in rec.position[0]]}


def run_search_job(job: Job, objective: Any, settings: Settings) -> Any:
    """Run one search job on a built objective; returns the :class:`~vbl_robust.search.SearchResult`."""
    from ..search import METHODS, maximize

    b = job.budget
    f = objective.torch if METHODS[job.method].needs_gradient else objective
    opts = dict(job.options)
    if settings.lipschitz is not None and "lipschitz" not in opts:
        opts["lipschitz"] = settings.lipschitz
    return maximize(
        f, job.box.box, job.method, max_evals=b.max_evals, max_iters=b.max_iters, max_seconds=b.max_seconds,
        stop_above=settings.eps_safe_m if b.stop_at_breach else None, seed=job.seed, **opts,
    )


def _reason(exc: BaseException) -> str:
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" (at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
    return f"{type(exc).__name__}: {exc}{where}"


def run_sample_task(task: SampleTask, detector: Any, settings: Settings, run_id: int | None = None,
                    ) -> Iterator[list[dict[str, Any]]]:
    """Run a sample's jobs in order; yield the rows to commit after each job."""
    from ..pipeline import Objective

    objectives: dict[str, Any] = {}
    breached: dict[str, dict[str, Any]] = {}  # chain -> breaching row
    for job in task.jobs:
        if job.chain is not None and job.chain in breached:
            continue  # recorded together with the breach
        t0 = time.perf_counter()
        try:
            if job.kind == "pnp":
                from .pnpcheck import pnp_comparison

                row = _base_row(job, run_id)
                row.update(status="done", verdict=None, payload_json=json.dumps(pnp_comparison(task.sample, detector, settings)),
                           nfev=1, nit=1, job_s=time.perf_counter() - t0)
                yield [row]
                continue
            label = job.box.label
            if label not in objectives:
                objectives[label] = Objective(task.sample, detector, job.box.box, pnp=settings.pnp,
                                              conf_threshold=settings.conf_threshold, penalty_m=settings.penalty_m)
            objective = objectives[label]
            result = run_search_job(job, objective, settings)
            image_error = getattr(objective, "image_error", "")
            if image_error:  # the pipeline penalised every evaluation: a failed sample, not a breach
                yield [failed_row(job, f"image unavailable: {image_error}", settings, run_id, time.perf_counter() - t0)]
                continue
            row = search_row(job, result, settings, run_id, time.perf_counter() - t0)
            if job.role == "main" and result.x is not None and hasattr(objective, "evaluate"):
                row["payload_json"] = json.dumps({"worst": worst_details(objective, result.x)})
        except Exception as exc:  # a sample the pipeline cannot handle is a recorded failure
            logger.warning("sample %s, job %s/%s failed: %s", job.sample_id, job.method, job.box and job.box.label,
                           _reason(exc))
            yield [failed_row(job, _reason(exc), settings, run_id, time.perf_counter() - t0)]
            continue
        rows = [row]
        if job.chain is not None and row["verdict"] == VERDICT_BREACH:
            breached[job.chain] = row
            rows += [implied_row(j, row, settings, run_id) for j in task.jobs
                     if j.chain == job.chain and j.box.level > job.box.level]
        yield rows
    if hasattr(task.sample, "drop_pixels"):
        task.sample.drop_pixels()
