"""How long a campaign will take on this machine, before it runs (``reproduce --estimate``).

Two numbers per campaign:

- an **upper bound** (:func:`planned_work`): every evaluation budget spent, every time budget run out;
- an **expectation** (:func:`expected_seconds`): a search that stops at its first breach spends, on an image where
  a share ``p`` of its box breaches, about ``(1 − (1 − p)^B) / p`` of its ``B`` evaluations (the expected
  evaluations of random sampling until the first breach: DIRECT-family searches usually need fewer, so this errs
  high); a chain of nested boxes stops at its first breached box. The shares ``p`` come from a :class:`Probe`:
  a few random points of each such box on each of a few probe images (the campaign's first images). Jobs without
  early stop count their whole budget; a time budget counts its seconds, or the evaluations it must reach at the
  measured rate if that takes longer.

Evaluations cost the measured rate of the black-box path, or of the gradient path for the methods that need a
gradient (APGD); ``workers`` processes share the jobs.

How a rate is measured (:func:`probe_rate`): as a campaign's workers run, in one thread (torch, the engine,
OpenCV), on :data:`PROBE_REPEATS` short probes that share the probe's seconds; the rate is the fastest probe's.
Work beside the probe slows some probes and never speeds one up, so the best of several short ones is close to
the rate of an idle core even while the machine is busy — one long probe averages the disturbance in, and several
threads wait on each other when a core is taken (the process clock then counts their spinning): a busy machine once
moved a single long probe by 2× (issue 50). :attr:`Probe.how` says how the rates were obtained.

A campaign already under way has better numbers: :func:`measured_remaining`, its jobs left at the pace its stored
jobs took, and :func:`with_stored_pace`, the evaluation rates its stored searches ran at.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..specs.campaign import CampaignSpec, Job
from ..specs.kinds import JobKind

#: Random points per box and probe image (:func:`probe`).
PROBE_POINTS = 8
#: Probe images (the campaign's first ones).
PROBE_IMAGES = 3
#: Short probes per rate (:func:`probe_rate`): the rate is the fastest one's.
PROBE_REPEATS = 5
#: Stored search jobs of a kind (black box / gradient) needed before their pace replaces a probe's rate.
MIN_STORED_JOBS = 3


@dataclass
class Probe:
    """What :func:`probe` measured: evaluations per second of the black-box and of the gradient path (one
    process, one thread), per box label the share of breaching points on each probe image, and ``how`` the rates
    were obtained (one line, for the estimate's output)."""

    rate: float
    grad_rate: float
    breach: dict[str, list[float]] = field(default_factory=dict)
    how: str = ""


@dataclass(frozen=True)
class RateProbe:
    """Evaluations per second of several short probes (seconds of ``clock``); the rate is the fastest's."""

    rates: tuple[float, ...]
    clock: str = "wall"

    @property
    def rate(self) -> float:
        return max(self.rates)

    def describe(self) -> str:
        """``best of 5 probes on the process clock (slowest 7.6)``."""
        return (f"best of {len(self.rates)} probe{'s' if len(self.rates) > 1 else ''} on the {self.clock} clock "
                f"(slowest {min(self.rates):.1f})")


def best_of_probes(call: Callable[[], int], seconds: float, *, repeats: int = PROBE_REPEATS,
                   now: Callable[[], float] = time.process_time, wall: Callable[[], float] = time.perf_counter,
                   clock: str = "process") -> RateProbe:
    """Rates of ``repeats`` probes that share ``seconds`` of wall time: each calls ``call()`` (which returns the
    evaluations it made) until its share of wall time is up, at least once, and divides the evaluations by the
    seconds of ``now`` they took."""
    if repeats < 1:
        raise ValueError(f"best_of_probes: repeats must be >= 1, got {repeats}")
    rates = []
    for _ in range(repeats):
        n, t0, c0 = 0, wall(), now()
        while n == 0 or wall() - t0 < seconds / repeats:
            n += call()
        rates.append(n / max(now() - c0, 1e-9))
    return RateProbe(tuple(rates), clock)


@contextmanager
def _one_thread() -> Iterator[None]:
    """torch and OpenCV on one thread, as a campaign's workers run (restored after)."""
    import cv2
    import torch

    from ..campaigns.work import one_core

    threads, cv_threads = torch.get_num_threads(), cv2.getNumThreads()
    one_core()
    try:
        yield
    finally:
        torch.set_num_threads(threads)
        cv2.setNumThreads(cv_threads)


def _jobs(spec: CampaignSpec, n_images: int) -> list[Job]:
    return spec.expand([(f"probe{i}", "") for i in range(n_images)])


def _grid_points(job: Job) -> int | None:
    counts = (job.options or {}).get("counts")
    return math.prod(int(c) for c in counts) if counts else None


def planned_work(spec: CampaignSpec, n_images: int) -> tuple[int, float]:
    """``(evaluations, seconds)`` an experiment can spend on ``n_images``: the evaluation budgets (grids: their
    points) of every job, and the time budgets of the time-bounded ones — an upper bound (early stops and chains
    cut it)."""
    evals, seconds = 0, 0.0
    for j in _jobs(spec, n_images):
        if j.kind == JobKind.PNP:
            evals += 1
            continue
        n = _grid_points(j) or j.budget.max_evals
        if n is not None:
            evals += n
        if j.budget.max_seconds is not None and j.budget.max_evals is None:
            seconds += j.budget.max_seconds
    return evals, seconds


def probe_rate(det: Any, seconds: float = 5.0, *, gradient: bool = False, clock: str = "wall",
               repeats: int = PROBE_REPEATS) -> RateProbe:
    """Evaluations per second of the audit objective (roll ± 15°, contrast) on one synthetic image, measured on the
    black-box path (or, ``gradient=True``, on the gradient path with a backward pass) in :data:`PROBE_REPEATS` short
    probes sharing ``seconds`` of wall time (:func:`best_of_probes`), in seconds of ``clock``
    (:data:`vbl_robust.search.base.CLOCKS`): ``"process"`` counts this process's CPU time, so waiting for a core that other
    work holds does not lower the rate. One thread, as a campaign's workers run (module docstring)."""
    import torch

    from ..campaigns.work import detector_for
    from ..pipeline import Objective
    from ..scenes.generate import generate
    from ..search.base import CLOCKS
    from ..space import ParameterBox

    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    rng = np.random.default_rng(0)
    batch = 4 if gradient else 32
    with _one_thread():
        obj = Objective(generate(1, seed=0)[0], detector_for(det), box)

        def call(n: int = batch) -> int:
            x = box.from_unit(rng.random((n, 2)))
            if gradient:
                theta = torch.tensor(x, dtype=torch.float64, requires_grad=True)
                with torch.enable_grad():
                    obj(theta).values.sum().backward()
            else:
                obj.evaluate(x)
            return n

        call(2)  # warm-up: model, pixels
        return best_of_probes(call, seconds, repeats=repeats, now=CLOCKS[clock], clock=clock)


def stored_pace(rows: Sequence[Any]) -> dict[bool, tuple[int, int, float]]:
    """Per kind (``True``: methods that need a gradient) the stored main search jobs' ``(jobs, evaluations, seconds
    of search)`` — their evaluation rate as they ran on this machine (the run's clock)."""
    from ..search.api import METHODS

    out: dict[bool, tuple[int, int, float]] = {}
    for r in rows:
        if r.kind != JobKind.SEARCH or r.method not in METHODS or not r.nfev or not (r.search_s and r.search_s > 0):
            continue
        g = METHODS[r.method].needs_gradient
        jobs, evals, secs = out.get(g, (0, 0, 0.0))
        out[g] = (jobs + 1, evals + int(r.nfev), secs + float(r.search_s))
    return out


def with_stored_pace(pr: Probe, rows: Sequence[Any], *, min_jobs: int = MIN_STORED_JOBS) -> Probe:
    """``pr`` with each rate replaced by the pace of a run's stored search jobs of that kind when at least
    ``min_jobs`` of them are stored (:func:`stored_pace`); :attr:`Probe.how` says which rate came from where."""
    pace = stored_pace(rows)
    rate, grad_rate, parts = pr.rate, pr.grad_rate, []
    for g, label in ((False, "black box"), (True, "gradient")):
        jobs, evals, secs = pace.get(g, (0, 0, 0.0))
        if jobs >= min_jobs:
            if g:
                grad_rate = evals / secs
            else:
                rate = evals / secs
            parts.append(f"{label}: pace of {jobs} stored jobs ({evals} evaluations in {secs:.0f} s of search)")
    if not parts:
        return pr
    return replace(pr, rate=rate, grad_rate=grad_rate, how="; ".join(parts) + (f"; else {pr.how}" if pr.how else ""))


def measured_remaining(spec: CampaignSpec, n_images: int, rows: Sequence[Any], pr: Probe,
                       workers: int = 1) -> tuple[int, float]:
    """``(jobs left, seconds left)`` of a campaign whose store already holds ``rows``: per (method, role) the jobs
    not stored yet times the stored jobs' mean worker seconds (``job_s``: the pace measured on this machine, as it
    was used); a (method, role) with nothing stored yet at the probe's expectation (its share of
    :func:`expected_seconds`). ``workers`` processes share the jobs."""
    from collections import Counter

    jobs = _jobs(spec, n_images)
    planned = Counter((j.method, j.role) for j in jobs)
    done = Counter((r.method, r.role) for r in rows)
    paces: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        if r.job_s is not None and r.job_s > 0:
            paces.setdefault((r.method, r.role), []).append(float(r.job_s))
    left_jobs, seconds, unmeasured = 0, 0.0, 0
    for key, n in planned.items():
        left = max(0, n - done[key])
        left_jobs += left
        if key in paces:
            seconds += left * float(np.mean(paces[key]))
        else:
            unmeasured += left
    if unmeasured:
        seconds += expected_seconds(spec, n_images, pr, 1) * unmeasured / max(1, len(jobs))
    return left_jobs, seconds / max(1, workers)


def stopping_boxes(specs: Sequence[CampaignSpec]) -> dict[str, Any]:
    """The boxes (by label) searched with an early stop in ``specs``: the ones whose breach share matters."""
    out: dict[str, Any] = {}
    for spec in specs:
        for blk in spec.blocks:
            if blk.kind == JobKind.SEARCH and any(b.stop_at_breach for b in blk.budgets):
                out.update({box.label: box for box in blk.boxes})
    return out


def probe(det: Any, specs: Sequence[CampaignSpec], samples: Sequence[Any], *, points: int = PROBE_POINTS,
          seconds: float = 5.0, seed: int = 0, clock: str = "wall") -> Probe:
    """Measure both evaluation rates (per second of ``clock``, :func:`probe_rate`: the best of short probes, one
    thread), and the share of ``points`` random points of each early-stopping box of ``specs`` that breach (error
    above the campaign's ε_safe) on each of ``samples``."""
    from ..campaigns.work import detector_for
    from ..pipeline import Objective

    with _one_thread():  # the detector is built as the workers build theirs (an engine keeps its thread count)
        detector = detector_for(det)
        boxes = stopping_boxes(specs)
        eps = specs[0].settings.eps_safe_m if specs else 1000.0
        rng = np.random.default_rng(seed)
        breach: dict[str, list[float]] = {label: [] for label in boxes}
        for sample in samples:
            for label, box in boxes.items():
                obj = Objective(sample, detector, box.box)
                loss = np.asarray(obj.evaluate(box.box.from_unit(rng.random((points, box.box.dim)))).loss)
                breach[label].append(float(np.mean(loss > eps)))
            if hasattr(sample, "drop_pixels"):
                sample.drop_pixels()
    rate = probe_rate(det, seconds, clock=clock)
    grad_rate = probe_rate(det, seconds, gradient=True, clock=clock)
    how = f"black box {rate.describe()}, gradient {grad_rate.describe()}; one thread"
    return Probe(rate.rate, grad_rate.rate, breach, how)


def expected_evals(p: float, budget: int) -> float:
    """Expected evaluations until the first breach (at most ``budget``) when each breaches with probability ``p``."""
    if p <= 0:
        return float(budget)
    if p >= 1:
        return 1.0
    return (1 - (1 - p) ** budget) / p


def expected_seconds(spec: CampaignSpec, n_images: int, pr: Probe, workers: int = 1) -> float:
    """Expected seconds of ``spec`` on ``n_images`` with ``workers`` processes (see the module docstring)."""
    from ..search.api import METHODS

    total = 0.0
    by_chain: dict[str, list[Job]] = {}
    for j in _jobs(spec, n_images):
        if j.kind == JobKind.PNP:
            total += 1 / pr.rate
            continue
        rate = pr.grad_rate if METHODS[j.method].needs_gradient else pr.rate
        n = _grid_points(j) or j.budget.max_evals
        if j.chain is not None:
            by_chain.setdefault(j.chain, []).append(j)
        elif j.budget.stop_at_breach and n is not None and j.box.label in pr.breach:
            total += float(np.mean([expected_evals(p, n) for p in pr.breach[j.box.label]] or [n])) / rate
        elif j.budget.max_seconds is not None:
            total += max(j.budget.max_seconds, (j.budget.min_evals or 0) / rate)
        else:
            total += (n or 0) / rate
    for chain in by_chain.values():  # nested boxes: a breach ends the chain
        rate = pr.grad_rate if METHODS[chain[0].method].needs_gradient else pr.rate
        n_probe = max((len(pr.breach.get(j.box.label, [])) for j in chain), default=0)
        per_probe = []
        for k in range(max(n_probe, 1)):
            reach, evals = 1.0, 0.0
            for j in sorted(chain, key=lambda j: j.box.level):
                shares = pr.breach.get(j.box.label) or [0.0]
                p, b = shares[min(k, len(shares) - 1)], j.budget.max_evals or 0
                evals += reach * expected_evals(p, b)
                reach *= (1 - p) ** b if p < 1 else 0.0
            per_probe.append(evals)
        total += float(np.mean(per_probe)) / rate
    return total / max(1, workers)
