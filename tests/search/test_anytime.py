"""Honest time budgets: stamped evaluations, bounded overshoot, and results read off a longer run
(:mod:`vbl_robust.search.anytime`). Time is a fake clock driven by the objective (no timing asserts)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vbl_robust.search.base as base_module
from vbl_robust.search.anytime import at_budget
from vbl_robust.search.api import DEFAULT_CHUNK, METHODS, anytime_methods, maximize
from vbl_robust.search.result import PARTIAL, SearchResult, Status

from .conftest import bumpy

ANYTIME = [m for m in sorted(METHODS) if METHODS[m].anytime]
OPTS = {"grid": {"counts": [41, 17]}}  # a grid sized by itself, not by a budget


class FakeClock:
    """Seconds advance only inside the objective: ``per_call`` + ``per_point`` × rows, plus ``overhead`` per
    call to the clock outside it (the method's own work)."""

    def __init__(self, per_call: float = 0.002, per_point: float = 0.01):
        self.t, self.per_call, self.per_point = 0.0, per_call, per_point
        self.calls: list[tuple[float, float, int]] = []  # (start, end, rows)

    def __call__(self) -> float:
        return self.t

    def wrap(self, f):
        def g(x):
            t0 = self.t
            self.t += self.per_call + self.per_point * len(x)
            self.calls.append((t0, self.t, len(x)))
            return f(x)
        return g


@pytest.fixture
def clock(monkeypatch):
    c = FakeClock()
    monkeypatch.setattr(base_module, "_clock", c)
    return c


def _same_run(a: SearchResult, b: SearchResult) -> None:
    assert a.nfev == b.nfev and a.nit == b.nit and a.n_failed == b.n_failed
    assert np.array_equal(a.xs, b.xs) and np.array_equal(a.fs, b.fs, equal_nan=True)
    assert np.array_equal(a.times, b.times) and a.reasons == b.reasons
    assert a.fun == b.fun and np.array_equal(a.x, b.x) and a.status is b.status
    assert [t.to_dict() for t in a.trace] == [t.to_dict() for t in b.trace]


def test_anytime_methods_are_all_but_apgd():
    assert set(anytime_methods()) == set(METHODS) - {"apgd"}


@pytest.mark.parametrize("method", ANYTIME)
def test_time_stopped_run_is_the_prefix_of_a_longer_run(method, box2, clock, monkeypatch):
    marks = (0.1, 0.25, 0.6)
    long = maximize(clock.wrap(bumpy), box2, method, max_seconds=1.5, time_marks=marks, **OPTS.get(method, {}))
    assert long.status in (Status.TIME_OUT, Status.CONVERGED)
    for t in marks:
        fresh = FakeClock()
        monkeypatch.setattr(base_module, "_clock", fresh)
        # the same deadlines before t (chunks are sized against them), then stopped at t
        short = maximize(fresh.wrap(bumpy), box2, method, max_seconds=t, time_marks=[m for m in marks if m < t],
                         **OPTS.get(method, {}))
        read = at_budget(long, seconds=t)
        _same_run(short, read)
        assert short.nfev > 0 and np.all(short.times <= t)


@pytest.mark.parametrize("method", ["random", "sobol", "grid"])
def test_evaluation_budget_is_the_prefix_for_sampling_methods(method, box2):
    long = maximize(bumpy, box2, method, max_evals=200, **OPTS.get(method, {}))
    for n in (1, 10, 64, 65, 150):
        short = maximize(bumpy, box2, method, max_evals=n, **OPTS.get(method, {}))
        read = at_budget(long, evals=n)
        assert np.array_equal(short.xs, read.xs) and np.array_equal(short.fs, read.fs)
        assert short.fun == read.fun and short.nfev == read.nfev == n


@pytest.mark.parametrize("method", ["georobust", "direct"])
def test_direct_evaluation_budget_differs_from_a_fitted_run_only_in_its_last_batch(method, box2):
    long = maximize(bumpy, box2, method, max_evals=400)
    short = maximize(bumpy, box2, method, max_evals=100)
    read = at_budget(long, evals=100)
    done = short.trace[-2].nfev  # batches before the one fitted to the budget
    assert np.array_equal(short.xs[:done], read.xs[:done]) and read.nfev == 100
    # the budget falls inside a batch of the long run (no batch of it ends at 100): the read-off's last batch is
    # that batch cut at the budget, marked partial
    assert 100 not in [t.nfev for t in long.trace]
    assert read.trace[-1].nfev == 100 and read.trace[-1].extra.get(PARTIAL) is True


def test_read_off_counts_only_evaluations_completed_by_the_budget(box2, clock):
    long = maximize(clock.wrap(bumpy), box2, "random", max_seconds=2.0)
    for t in (0.0, 0.05, 0.3, 1.0, 2.0):
        r = at_budget(long, seconds=t)
        assert r.nfev == int(np.sum(long.times <= t)) and np.all(r.times <= t)
        assert r.fun == np.max(r.fs) if r.nfev else math.isnan(r.fun)  # nothing read yet: no value
        assert r.nit == len(r.trace) and (not r.trace or r.trace[-1].nfev == r.nfev)
        assert r.elapsed <= t
    assert at_budget(long, seconds=0.0).x is None


def test_overshoot_is_at_most_one_small_chunk(box2, clock):
    r = maximize(clock.wrap(bumpy), box2, "random", max_seconds=1.0)  # random's batch is 64 points
    starts = [s for s, _, _ in clock.calls]
    assert max(starts) < 1.0  # no chunk starts after the budget
    overshoot = clock.calls[-1][1] - 1.0
    assert 0.0 <= overshoot <= clock.per_call + clock.per_point * clock.calls[-1][2]
    assert clock.calls[0][2] == 1 and max(n for _, _, n in clock.calls) <= DEFAULT_CHUNK
    assert clock.calls[-1][2] <= 2  # chunks shrink towards the deadline
    assert r.nfev >= 0.9 * 1.0 / (clock.per_point + clock.per_call / DEFAULT_CHUNK) * 0.5


def test_cut_batch_is_recorded_but_not_told_to_the_method(box2, clock):
    r = maximize(clock.wrap(bumpy), box2, "georobust", max_seconds=0.3)
    last = r.trace[-1]
    assert r.status is Status.TIME_OUT and last.nfev == r.nfev
    assert sum(t.batch_size for t in r.trace) == r.nfev


def test_min_evals_defers_the_time_stop(box2, clock):
    r = maximize(clock.wrap(bumpy), box2, "random", max_seconds=0.2, min_evals=100, batch_size=16)
    assert r.nfev >= 100 and r.status is Status.TIME_OUT
    assert at_budget(r, seconds=0.2).nfev < 100 and at_budget(r, evals=100).nfev == 100


def test_untimed_runs_call_the_objective_once_per_batch(box2, clock):
    r = maximize(clock.wrap(bumpy), box2, "random", max_evals=150)
    assert [n for _, _, n in clock.calls] == [64, 64, 22] and len(r.times) == 150


def test_times_round_trip_through_dict(box2, clock):
    r = maximize(clock.wrap(bumpy), box2, "direct", max_seconds=0.2)
    back = SearchResult.from_dict(r.to_dict())
    assert np.array_equal(back.times, r.times)
    assert SearchResult.from_dict({**r.to_dict(), "times": None}).times is None


@pytest.mark.parametrize("bad", [{"seconds": -1.0}, {"evals": -2}, {}])
def test_at_budget_refuses_bad_budgets(bad, box2):
    r = maximize(bumpy, box2, "random", max_evals=10)
    with pytest.raises(ValueError, match="at_budget: (seconds must be|evals must be|give seconds)"):
        at_budget(r, **bad)


def test_time_budget_needs_stamps(box2):
    from dataclasses import replace

    r = replace(maximize(bumpy, box2, "random", max_evals=10), times=None)
    assert at_budget(r, evals=5).nfev == 5
    with pytest.raises(ValueError, match="time stamps"):
        at_budget(r, seconds=1.0)


def test_bad_time_options(box2):
    with pytest.raises(ValueError, match="time_marks"):
        maximize(bumpy, box2, "random", max_evals=10, time_marks=(0.5,))
    with pytest.raises(ValueError, match="min_evals"):
        maximize(bumpy, box2, "random", max_evals=10, min_evals=5)
    with pytest.raises(ValueError, match="chunk_size"):
        maximize(bumpy, box2, "random", max_seconds=1.0, chunk_size=0)
