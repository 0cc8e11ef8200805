"""What a worker does: run the jobs of one sample and turn each outcome into a store row.

The unit of work is a :class:`SampleTask` (one sample + its pending jobs): the objective is built once per
(sample, box) and the detector once per process (:func:`detector_for`), never per job. :func:`run_sample_task`
yields, job after job, the rows to commit together (usually one; a breach in a chain brings the implied rows
of the larger boxes with it, so a chain is never half-recorded).

Rows are :class:`~vbl_robust.store.rows.JobRow` s. Every search evaluation carries its failure reason (no
detection, PnP failure, …) from the objective into the search result and the row (``n_failed``, ``failures``,
``worst_reason``, the reason of every stored point); the search itself sees the penalty value, as before.

A job the tool cannot complete (an image that cannot be loaded, a method that cannot run on the detector, an
exception in our code or in the detector) gives a row with status and verdict "not measured", its reason as
``"<kind>: <detail>"`` (:class:`~vbl_robust.constants.NotMeasured`, :func:`not_measured_reason` draws the line) and
no worst error; it enters no rate, and the campaign goes on.
"""

from __future__ import annotations

import json
import logging
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..constants import NotMeasured, NotMeasuredError, Verdict
from ..specs.campaign import Job
from ..specs.kinds import JobKind, JobStatus, Role
from ..specs.settings import PipelineSettings
from ..store.payloads import (
    Nominal,
    RiskPayload,
    RiskStratum,
    SequenceFacts,
    SequenceFrames,
    SequencePayload,
    WorstPayload,
    WorstPoint,
)
from ..store.rows import Corners, JobRow, Points, now_iso
from .provenance import DetectorSpec
from .rebuild import finite_or_none, result_fields, search_kwargs

if TYPE_CHECKING:  # typing only: the pipeline (torch) is imported where an objective is built
    from ..data.sample import Sample
    from ..data.sequence import ApproachSequence
    from ..detect.base import Detector
    from ..pipeline import SearchObjective
    from ..risk import RiskResult, ThetaDistribution
    from ..search.result import SearchResult
    from ..space import ParameterBox

logger = logging.getLogger(__name__)
#: Where vbl-robust's own code lives (:func:`not_measured_reason` tells its frames from a user's).
_PACKAGE_DIR = "/vbl_robust/"
#: The objective's methods that call a detector (an exception below them is the detector's).
_DETECTOR_CALLS = frozenset({"select_at", "_detect_all"})

_DETECTORS: dict[str, Detector] = {}
#: Points per objective call of a breach-stopped search on a CPU (:func:`breach_chunk`).
CPU_BREACH_CHUNK = 4


def one_core() -> None:
    """A worker computes on one core: torch's threads and OpenCV's (the black-box views' warps) — a worker per core,
    never several threads fighting over one."""
    import cv2
    import torch

    torch.set_num_threads(1)
    cv2.setNumThreads(1)


def detector_for(spec: DetectorSpec) -> Detector:
    """The detector of ``spec``, built once per process (a model is loaded once, not per job)."""
    key = json.dumps(spec.to_dict(), sort_keys=True)
    if key not in _DETECTORS:
        _DETECTORS[key] = spec.build()
    return _DETECTORS[key]


def build_objective(sample: Sample | ApproachSequence, detector: Detector, box: ParameterBox,
                    settings: PipelineSettings) -> SearchObjective:
    """The objective a search job maximises over ``box``: the error of one image
    (:class:`~vbl_robust.pipeline.Objective`), or in a sequence campaign (``settings.sustain`` set) the error one θ
    sustains over ``sustain`` consecutive frames of an approach sequence
    (:class:`~vbl_robust.sequences.objective.SequenceObjective`)."""
    if settings.sustain is not None:
        from ..sequences.objective import SequenceObjective

        return SequenceObjective(sample, detector, box, settings.pnp, sustain=settings.sustain,
                                 conf_threshold=settings.conf_threshold, penalty_m=settings.penalty_m)
    from ..pipeline import Objective

    return Objective(sample, detector, box, pnp=settings.pnp, conf_threshold=settings.conf_threshold,
                     penalty_m=settings.penalty_m, max_reproj_px=settings.monitor_px,
                     max_sigma_m=settings.monitor_sigma_m)


@dataclass
class SampleTask:
    """One sample and its pending jobs (in campaign order)."""

    sample: Sample | ApproachSequence
    jobs: Sequence[Job]


def _row(job: Job, run_id: int | None, status: JobStatus, **outcome: Any) -> JobRow:
    return JobRow(
        key=job.key, experiment=job.experiment, kind=job.kind, role=job.role, method=job.method,
        sample_id=job.sample_id, sample_index=job.sample_index, status=status, run_id=run_id,
        box=job.box, budget=job.budget, seed=job.seed, options=dict(job.options), chain=job.chain,
        finished_at=now_iso(), **outcome,
    )


def unmeasured_row(job: Job, kind: NotMeasured, detail: str, run_id: int | None = None, job_s: float = 0.0,
                   ) -> JobRow:
    """A job the tool could not complete: status and verdict NOT_MEASURED, reason ``"<kind>: <detail>"``, no worst
    error (it enters no rate)."""
    return _row(job, run_id, JobStatus.NOT_MEASURED, reason=f"{NotMeasured(kind).value}: {detail}", worst_m=None,
                verdict=Verdict.NOT_MEASURED, n_failed=0, job_s=job_s)


def not_measured_reason(exc: BaseException) -> tuple[NotMeasured, str]:
    """Why a job that raised ``exc`` is not measured, and the one line a user reads (no Python repr, no source
    location: those go to the log). The one place the tool's failures are told apart: a
    :class:`~vbl_robust.constants.NotMeasuredError` says its kind; an exception raised inside the detector (the
    innermost frame of vbl-robust's own is in ``detect/``, or is the objective's call of the detector, below which a
    user's model or plugin raised) is ``DETECTOR_ERROR``; any other is ``TOOL_ERROR``."""
    if isinstance(exc, NotMeasuredError):
        return exc.reason, str(exc)
    ours = [f for f in traceback.extract_tb(exc.__traceback__) if _PACKAGE_DIR in f.filename]
    in_detector = bool(ours) and ("/detect/" in ours[-1].filename or ours[-1].name in _DETECTOR_CALLS)
    kind = NotMeasured.DETECTOR_ERROR if in_detector else NotMeasured.TOOL_ERROR
    text = str(exc).splitlines()[0] if str(exc) else ""
    return kind, f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def search_row(job: Job, result: Any, settings: PipelineSettings, run_id: int | None, job_s: float) -> JobRow:
    """Row of a finished search (a :class:`~vbl_robust.search.result.SearchResult`)."""
    return _row(job, run_id, JobStatus.DONE, job_s=job_s,
                **result_fields(result, settings.eps_safe_m, settings.penalty_m))


def implied_row(job: Job, breach: JobRow, settings: PipelineSettings, run_id: int | None) -> JobRow:
    """A larger box of a chain after a breach at a smaller, nested box: the same breach point lies in it."""
    return _row(job, run_id, JobStatus.IMPLIED, reason=f"breach found at {breach.box_label}", worst_m=breach.worst_m,
                worst_x=breach.worst_x, verdict=Verdict.BREACH, worst_reason=breach.worst_reason,
                worst_corners=breach.worst_corners, search_s=0.0, job_s=0.0)


def worst_details(objective: SearchObjective, x: np.ndarray) -> tuple[WorstPoint, Corners | None]:
    """What the pipeline gives at the worst point (one more evaluation): the payload's top confidence, position
    error and estimated position (the failure reason is the one the search recorded, ``JobRow.worst_reason``), and
    the four corners of the selected candidate in the sample's pixels (``JobRow.worst_corners``; None when the
    detector gave none). A detector that says how sure it is adds the corners' σ (``corner_sigma_px``, 4 × 2, the
    sample's pixels) and their propagation to the position (``position_sigma_m``)."""
    rec = objective.evaluate(np.asarray(x, dtype=np.float64)[None])
    conf = float(rec.conf[0])
    err = float(rec.error_m[0])
    kp = np.asarray(rec.keypoints[0], dtype=np.float64)
    corners = tuple((float(u), float(v)) for u, v in kp) if kp.shape == (4, 2) and np.isfinite(kp).all() else None
    sigma = None if rec.keypoint_sigma is None else tuple(tuple(finite_or_none(float(v)) for v in c)
                                                          for c in rec.keypoint_sigma[0])
    return WorstPoint(finite_or_none(conf), finite_or_none(err), tuple(finite_or_none(float(v)) for v in rec.position[0]), sigma,
                      None if sigma is None else finite_or_none(float(rec.position_sigma_m[0]))), corners


def nominal_details(objective: SearchObjective) -> Nominal:
    """The unperturbed image's facts (one evaluation at the identity θ: roll 0, contrast 1, …), stored beside the
    worst point as the payload's ``nominal``: ``error_m`` = L(0) (the objective: the penalty where it failed),
    ``reason`` (``""``: a pose), ``conf`` and the predicted ``corners`` (sample's pixels, TR TL BL BR; None: none)."""
    from ..sequences.objective import nominal_theta

    rec = objective.evaluate(nominal_theta(objective.box))
    kp = np.asarray(rec.keypoints[0], dtype=np.float64)
    return Nominal(finite_or_none(float(rec.loss[0])), rec.reason[0], finite_or_none(float(rec.conf[0])),
                   tuple(map(tuple, kp.tolist())) if kp.shape == (4, 2) and np.isfinite(kp).all() else None)


def sequence_details(objective: SearchObjective, x: np.ndarray, eps_safe_m: float) -> SequencePayload:
    """What a sequence job stores about its worst θ (two more evaluations of the sequence): the breach facts of the
    worst θ and of the unperturbed θ (:meth:`~vbl_robust.sequences.objective.SequenceRecord.summary` at ``eps_safe_m``, with
    each frame's error and failure reason) and the frames (image id, index, time, distance from the runway
    threshold); JSON-safe (non-finite numbers as None)."""
    from ..sequences.objective import nominal_theta

    seq = objective.sequence
    frames = SequenceFrames(tuple(str(s.id) for s in seq.samples), tuple(int(i) for i in seq.frame_index),
                            tuple(finite_or_none(float(t)) for t in seq.times), tuple(float(d) for d in seq.distances_m))
    facts = []
    for theta in (np.asarray(x, dtype=np.float64)[None], nominal_theta(objective.box)):
        rec = objective.evaluate(theta)
        summary = {k: (finite_or_none(v) if isinstance(v, float) else v) for k, v in rec.summary(0, eps_safe_m).items()}
        facts.append(SequenceFacts.of_summary(summary, [finite_or_none(float(v)) for v in rec.loss[:, 0]],
                                              [r[0] for r in rec.reasons]))
    return SequencePayload(frames, *facts)


def run_search_job(job: Job, objective: SearchObjective, settings: PipelineSettings) -> SearchResult:
    """Run one search job on a built objective; returns the :class:`~vbl_robust.search.result.SearchResult` (with the
    failure reason and completion time of every evaluated point).

    A time-budgeted job first warms the objective up with one evaluation of the box centre outside the search's
    clock (image loading, first detector call), so no method pays that one-off cost inside its budget; then the
    search evaluates in chunks of the objective's detector batch (``batch_size``) and stops between chunks. A
    budget that reads smaller budgets off the run (``Budget.reads``) passes them on: the run goes on until
    ``max(read_evals)`` evaluations are done and sizes its chunks against each of ``read_seconds``."""
    from ..search.api import METHODS, maximize
    from ..search.base import use_clock

    b = job.budget
    needs_gradient = METHODS[job.method].needs_gradient
    f = objective  # a NumPy θ is the black box, a torch θ (gradient methods) the differentiable path
    timing: dict[str, Any] = {"chunk_size": breach_chunk(objective)}
    if b.max_seconds is not None:
        _warm_up(f, job.box.box, needs_gradient)
        timing = {"min_evals": b.min_evals, "time_marks": b.read_seconds, "chunk_size": int(objective.batch_size)}
    kwargs = search_kwargs(job.options, b, eps_safe_m=settings.eps_safe_m, lipschitz=settings.lipschitz,
                           seed=job.seed)
    with use_clock(settings.clock):
        return maximize(f, job.box.box, job.method, max_seconds=b.max_seconds, **timing, **kwargs)


def risk_row(job: Job, objective: SearchObjective, settings: PipelineSettings, run_id: int | None, t0: float) -> JobRow:
    """Run a failure-probability job (:func:`vbl_robust.risk.estimate_risk`; options: ``dist``, ``tau``,
    ``delta``, ``guide_evals``) and its row: every draw as the row's points, the estimate, its interval and the
    verdict in the ``risk`` payload; worst error and verdict as a search row's (the largest L drawn), and the corners
    predicted there (:func:`worst_details`: one more evaluation)."""
    from ..risk import ThetaDistribution, estimate_risk

    opts = dict(job.options)
    dist = ThetaDistribution.over(job.box.box, {k: tuple(v) for k, v in (opts.pop("dist", None) or {}).items()})
    tau, delta = float(opts.pop("tau")), float(opts.pop("delta"))
    t_search = time.perf_counter()
    r = estimate_risk(objective, dist, job.method, eps_safe_m=settings.eps_safe_m, tau=tau, delta=delta,
                      max_evals=int(job.budget.max_evals), seed=job.seed, **opts)
    fs = np.where(np.isfinite(r.fs), r.fs, settings.penalty_m)
    i = int(np.argmax(fs))
    worst = float(fs[i])
    t_search = time.perf_counter() - t_search
    return _row(job, run_id, JobStatus.DONE, worst_m=worst, worst_x=dict(zip(job.box.box.names, map(float, r.xs[i]),
                                                                             strict=True)),
                worst_corners=worst_details(objective, r.xs[i])[1],
                verdict=Verdict.BREACH if worst > settings.eps_safe_m else Verdict.NO_BREACH_FOUND,
                nfev=r.evaluations, nit=1, n_failed=sum(1 for x in r.reasons if x),
                failures=dict(sorted(Counter(x for x in r.reasons if x).items())), worst_reason=r.reasons[i],
                search_status="budget_exhausted", points=Points(r.xs, r.fs, r.reasons),
                payload=risk_payload(r, tau, delta, dist), search_s=t_search,
                job_s=time.perf_counter() - t0)


def risk_payload(r: RiskResult, tau: float, delta: float, dist: ThetaDistribution) -> dict[str, Any]:
    """A risk job row's payload (:class:`~vbl_robust.store.payloads.RiskPayload`) of the estimate ``r``."""
    return RiskPayload(r.method, r.p_fail, r.eps_safe_m, r.ci.low, r.ci.high, r.ci.level, r.ci.method, r.verdict,
                       tau, delta, r.evaluations, dist.to_dict(),
                       tuple(RiskStratum(s.mass, s.k, s.n, a, b)
                             for s, (a, b) in zip(r.strata, r.split, strict=True))).to_json()


def breach_chunk(objective: SearchObjective) -> int:
    """Points per objective call of a search that stops at its first breach: the whole detector batch on a GPU
    (a batch costs about as much as one point there), :data:`CPU_BREACH_CHUNK` on a CPU (a point costs about the
    same in any chunk, so a small chunk wastes little after the breach). The search's record does not depend on
    it (:func:`~vbl_robust.search.maximize`)."""
    batch = int(objective.batch_size)
    return batch if objective.device.type != "cpu" else min(batch, CPU_BREACH_CHUNK)


def _warm_up(f: Callable[[Any], Any], box: Any, needs_gradient: bool) -> None:
    """One evaluation of the box centre (its value is discarded)."""
    centre = ((np.asarray(box.lower, dtype=np.float64) + np.asarray(box.upper, dtype=np.float64)) / 2)[None]
    if needs_gradient:
        import torch

        theta = torch.tensor(centre, dtype=torch.float64, requires_grad=True)
        with torch.enable_grad():
            f(theta)
    else:
        f(centre)


@dataclass
class _SampleRun:
    """What the jobs of one sample share: the sample, the detector, the settings, and the objectives built so far
    (one per box) with their nominal L(0)."""

    task: SampleTask
    detector: Detector
    settings: PipelineSettings
    run_id: int | None
    objectives: dict[str, SearchObjective] = field(default_factory=dict)
    nominals: dict[str, Nominal] = field(default_factory=dict)

    def objective(self, job: Job) -> SearchObjective:
        label = job.box.label
        if label not in self.objectives:
            self.objectives[label] = build_objective(self.task.sample, self.detector, job.box.box, self.settings)
        return self.objectives[label]

    def unreadable(self, job: Job, objective: SearchObjective, t0: float) -> JobRow | None:
        """The row of a job whose input the tool cannot read (not measured, never a breach), else None."""
        image_error = objective.image_error
        if not image_error:
            return None
        named = image_error if job.sample_id in image_error else f"sample {job.sample_id}: {image_error}"
        return unmeasured_row(job, NotMeasured.INPUT_UNAVAILABLE, named, self.run_id, time.perf_counter() - t0)


def _pnp_job(job: Job, run: _SampleRun, t0: float) -> JobRow:
    from .pnpcheck import pnp_comparison

    payload = pnp_comparison(run.task.sample, run.detector, run.settings)
    return _row(job, run.run_id, JobStatus.DONE, payload=payload, nfev=1, nit=1, job_s=time.perf_counter() - t0)


def _risk_job(job: Job, run: _SampleRun, t0: float) -> JobRow:
    objective = run.objective(job)
    if (unread := run.unreadable(job, objective, t0)) is not None:
        return unread
    return risk_row(job, objective, run.settings, run.run_id, t0)


def _search_job(job: Job, run: _SampleRun, t0: float) -> JobRow:
    objective = run.objective(job)
    if (unread := run.unreadable(job, objective, t0)) is not None:
        return unread
    settings = run.settings
    result = run_search_job(job, objective, settings)
    row = search_row(job, result, settings, run.run_id, time.perf_counter() - t0)
    if job.role != Role.MAIN or result.x is None:
        return row
    if settings.sustain is not None:
        return row.replace(payload=sequence_details(objective, result.x, settings.eps_safe_m).to_json())
    details, corners = worst_details(objective, result.x)
    label = job.box.label
    if label not in run.nominals:  # L(0): one evaluation per image and box, shared by its jobs
        run.nominals[label] = nominal_details(objective)
    return row.replace(payload=WorstPayload(details, run.nominals[label]).to_json(), worst_corners=corners)


#: How the worker runs a job of each kind: ``JOB_RUNNERS[job.kind](job, run, t0)`` gives its row.
JOB_RUNNERS: dict[JobKind, Callable[[Job, _SampleRun, float], JobRow]] = {
    JobKind.SEARCH: _search_job,
    JobKind.PNP: _pnp_job,
    JobKind.RISK: _risk_job,
}


def run_sample_task(task: SampleTask, detector: Detector, settings: PipelineSettings, run_id: int | None = None,
                    ) -> Iterator[list[JobRow]]:
    """Run a sample's jobs in order; yield the rows to commit after each job."""
    run = _SampleRun(task, detector, settings, run_id)
    breached: dict[str, JobRow] = {}  # chain -> breaching row
    for job in task.jobs:
        if job.chain is not None and job.chain in breached:
            continue  # recorded together with the breach
        t0 = time.perf_counter()
        try:
            row = JOB_RUNNERS[job.kind](job, run, t0)
        except Exception as exc:  # the tool could not complete the job: not measured, recorded, the campaign goes on
            kind, detail = not_measured_reason(exc)
            logger.warning("sample %s, job %s/%s not measured (%s): %s", job.sample_id, job.method,
                           job.box and job.box.label, kind.value, detail)
            logger.debug("traceback of the job not measured", exc_info=exc)
            yield [unmeasured_row(job, kind, detail, run_id, time.perf_counter() - t0)]
            continue
        rows = [row]
        if job.chain is not None and row.verdict == Verdict.BREACH:
            breached[job.chain] = row
            rows += [implied_row(j, row, settings, run_id) for j in task.jobs
                     if j.chain == job.chain and j.box.level > job.box.level]
        yield rows
    task.sample.drop_pixels()
