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

A campaign already under way has a better number: :func:`measured_remaining`, its jobs left at the pace its stored
jobs took.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .spec import CampaignSpec, Job

#: Random points per box and probe image (:func:`probe`).
PROBE_POINTS = 8
#: Probe images (the campaign's first ones).
PROBE_IMAGES = 3


@dataclass
class Probe:
    """What :func:`probe` measured: evaluations per second of the black-box and of the gradient path (one
    process, one thread), and per box label the share of breaching points on each probe image."""

    rate: float
    grad_rate: float
    breach: dict[str, list[float]] = field(default_factory=dict)


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
        if j.kind == "pnp":
            evals += 1
            continue
        n = _grid_points(j) or j.budget.max_evals
        if n is not None:
            evals += n
        if j.budget.max_seconds is not None and j.budget.max_evals is None:
            seconds += j.budget.max_seconds
    return evals, seconds


def probe_rate(det: Any, seconds: float = 5.0, *, gradient: bool = False, clock: str = "wall") -> float:
    """Evaluations per second of the audit objective (roll ± 15°, contrast) on one synthetic image, measured on the
    black-box path (or, ``gradient=True``, on the gradient path with a backward pass), for ``seconds`` of wall time;
    seconds of ``clock`` (:data:`vbl_robust.search.CLOCKS`): ``"process"`` counts this process's CPU time, so other
    work on the machine does not lower the rate (the rate of an idle core)."""
    import torch

    from ..pipeline import Objective
    from ..scenes import generate
    from ..search import CLOCKS
    from ..space import ParameterBox
    from .work import detector_for

    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    obj = Objective(generate(1, seed=0)[0], detector_for(det), box)
    rng = np.random.default_rng(0)
    batch = 4 if gradient else 32

    def call(n: int) -> None:
        x = box.from_unit(rng.random((n, 2)))
        if gradient:
            theta = torch.tensor(x, dtype=torch.float64, requires_grad=True)
            with torch.enable_grad():
                obj(theta).values.sum().backward()
        else:
            obj.evaluate(x)

    call(2)  # warm-up: model, pixels
    now = CLOCKS[clock]
    n, t0, c0 = 0, time.perf_counter(), now()
    while time.perf_counter() - t0 < seconds:
        call(batch)
        n += batch
    return n / (now() - c0)


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
            if blk.kind == "search" and any(b.stop_at_breach for b in blk.budgets):
                out.update({box.label: box for box in blk.boxes})
    return out


def probe(det: Any, specs: Sequence[CampaignSpec], samples: Sequence[Any], *, points: int = PROBE_POINTS,
          seconds: float = 5.0, seed: int = 0, clock: str = "wall") -> Probe:
    """Measure both evaluation rates (per second of ``clock``, :func:`probe_rate`), and the share of ``points``
    random points of each early-stopping box of ``specs`` that breach (error above the campaign's ε_safe) on each
    of ``samples``."""
    from ..pipeline import Objective
    from .work import detector_for

    detector = detector_for(det)
    boxes = stopping_boxes(specs)
    eps = specs[0].eps_safe_m if specs else 1000.0
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
    return Probe(rate, grad_rate, breach)


def expected_evals(p: float, budget: int) -> float:
    """Expected evaluations until the first breach (at most ``budget``) when each breaches with probability ``p``."""
    if p <= 0:
        return float(budget)
    if p >= 1:
        return 1.0
    return (1 - (1 - p) ** budget) / p


def expected_seconds(spec: CampaignSpec, n_images: int, pr: Probe, workers: int = 1) -> float:
    """Expected seconds of ``spec`` on ``n_images`` with ``workers`` processes (see the module docstring)."""
    from ..search import METHODS

    total = 0.0
    by_chain: dict[str, list[Job]] = {}
    for j in _jobs(spec, n_images):
        if j.kind == "pnp":
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
