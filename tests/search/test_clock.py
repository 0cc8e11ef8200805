"""Search clocks: a time budget on process (CPU) time is not spent by waiting, one on wall time is."""

from __future__ import annotations

import time

import numpy as np
import pytest

from vbl_robust.search.api import maximize
from vbl_robust.search.base import CLOCKS, use_clock
from vbl_robust.search.result import Status
from vbl_robust.space import ParameterBox


def _sleepy(x):
    time.sleep(0.05)  # wall time passes, this process's CPU time hardly does
    return -(x**2).sum(axis=1)


def test_process_clock_does_not_count_waiting():
    box = ParameterBox({"a": (-1.0, 1.0)})
    wall = maximize(_sleepy, box, "random", max_seconds=0.2, max_evals=40, seed=0)
    with use_clock("process"):
        cpu = maximize(_sleepy, box, "random", max_seconds=0.2, max_evals=40, seed=0)
    assert wall.status is Status.TIME_OUT and wall.nfev < 40
    assert cpu.status is Status.BUDGET_EXHAUSTED and cpu.nfev == 40
    assert np.all(np.diff(cpu.times) >= 0) and cpu.times[-1] < 0.2


def test_use_clock_restores_and_refuses_unknown_names():
    import vbl_robust.search.base as base

    before = base._clock
    with use_clock("process"):
        assert base._clock is CLOCKS["process"]
    assert base._clock is before
    with pytest.raises(ValueError, match="clock must be one of"):
        with use_clock("gpu"):
            pass
