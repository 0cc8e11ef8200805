"""The estimate's rate probe (issue 50): the best of short probes, the pace of stored jobs, and how each was obtained.

No timing asserts: the clocks are fakes that the probed call advances.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from vbl_robust.paper.estimate import (
    Probe,
    RateProbe,
    best_of_probes,
    probe_rate,
    stored_pace,
    with_stored_pace,
)


class FakeClocks:
    """A wall clock and a CPU clock that each call advances: ``cpu_per_call`` seconds of CPU per call, and twice the
    wall time of it (a machine shared with one other process); ``slow`` calls cost ``slowdown`` times the CPU."""

    def __init__(self, cpu_per_call: float, slow: set[int] = frozenset(), slowdown: float = 2.0):
        self.t_wall = self.t_cpu = 0.0
        self.calls, self.cpu_per_call, self.slow, self.slowdown = 0, cpu_per_call, slow, slowdown

    def call(self) -> int:
        cost = self.cpu_per_call * (self.slowdown if self.calls in self.slow else 1.0)
        self.calls += 1
        self.t_cpu += cost
        self.t_wall += 2.0 * cost
        return 32

    def wall(self) -> float:
        return self.t_wall

    def cpu(self) -> float:
        return self.t_cpu


def test_the_best_short_probe_is_the_rate_of_an_undisturbed_core():
    # 32 evaluations per call at 0.1 CPU s: 320 evaluations/s; calls 3 to 9 (the second probe) run at half speed
    clocks = FakeClocks(0.1, slow=set(range(3, 10)))
    r = best_of_probes(clocks.call, 3.0, repeats=5, now=clocks.cpu, wall=clocks.wall, clock="process")
    assert len(r.rates) == 5 and r.rate == pytest.approx(320.0)
    assert min(r.rates) < 250.0  # the disturbed probe is measured, and not taken
    assert r.describe().startswith("best of 5 probes on the process clock (slowest ")


def test_each_probe_makes_at_least_one_call():
    clocks = FakeClocks(10.0)
    r = best_of_probes(clocks.call, 0.001, repeats=3, now=clocks.cpu, wall=clocks.wall)
    assert clocks.calls == 3 and r.rates == pytest.approx((3.2, 3.2, 3.2))
    with pytest.raises(ValueError, match="repeats"):
        best_of_probes(clocks.call, 1.0, repeats=0)


def _row(method, nfev, search_s, kind="search"):
    return SimpleNamespace(kind=kind, method=method, nfev=nfev, search_s=search_s)


def test_stored_pace_replaces_a_rate_with_enough_stored_jobs():
    pr = Probe(10.0, 4.0, {"b": [0.5]}, how="black box best of 5 probes")
    rows = [_row("georobust", 300, 20.0), _row("random", 100, 10.0), _row("georobust", 200, 20.0),
            _row("apgd", 40, 20.0), _row("pnp", 1, 1.0, kind="pnp"), _row("georobust", 0, 5.0),
            _row("random", 50, None)]
    pace = stored_pace(rows)
    assert pace == {False: (3, 600, 50.0), True: (1, 40, 20.0)}
    got = with_stored_pace(pr, rows)
    assert got.rate == pytest.approx(12.0) and got.grad_rate == 4.0 and got.breach == pr.breach
    assert got.how == ("black box: pace of 3 stored jobs (600 evaluations in 50 s of search); "
                       "else black box best of 5 probes")
    assert with_stored_pace(pr, rows[:2]) is pr  # too few: the probe's rates stand
    both = with_stored_pace(pr, rows, min_jobs=1)
    assert both.grad_rate == pytest.approx(2.0) and "gradient: pace of 1 stored jobs" in both.how


def test_probe_rate_runs_on_one_thread_and_restores_the_threads():
    import cv2
    import torch

    from vbl_robust.detect.shipped import DetectorSpec

    before = (torch.get_num_threads(), cv2.getNumThreads())
    r = probe_rate(DetectorSpec("oracle"), 0.05, repeats=2, clock="process")
    assert isinstance(r, RateProbe) and len(r.rates) == 2 and min(r.rates) > 0
    assert (torch.get_num_threads(), cv2.getNumThreads()) == before
