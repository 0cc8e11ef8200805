"""Random, Sobol and grid searches."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import qmc

from vbl_robust.constants import Verdict
from vbl_robust.search.api import maximize
from vbl_robust.search.result import Status
from vbl_robust.search.sampling import GridSearch
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.7, 1.4)})


def _f(x):
    return np.cos(x[:, 0] / 5.0) + x[:, 1]


def test_random_is_uniform_batched_and_seeded():
    r = maximize(_f, BOX, "random", max_evals=1000, batch_size=100, seed=7)
    assert [row.batch_size for row in r.trace] == [100] * 10
    u = BOX.to_unit(r.xs)
    expected = np.random.default_rng(7).random((1000, 2))
    assert np.allclose(u, expected)


def test_sobol_is_scipy_scrambled_sequence_in_order():
    r = maximize(_f, BOX, "sobol", max_evals=96, batch_size=32, seed=5)
    expected = qmc.Sobol(2, scramble=True, rng=np.random.default_rng(5)).random(128)[:96]
    assert np.allclose(BOX.to_unit(r.xs), expected)


def test_grid_counts_order_and_convergence():
    r = maximize(_f, BOX, "grid", counts=[3, 5], batch_size=4, max_evals=100)
    assert r.nfev == 15 and r.status is Status.CONVERGED and r.nit == 4
    assert np.allclose(r.xs[:6], [[-15, 0.7], [-15, 0.875], [-15, 1.05], [-15, 1.225], [-15, 1.4], [0, 0.7]])
    assert r.x.tolist() == [0.0, 1.4] and r.fun == pytest.approx(2.4)


def test_grid_step_and_budget_default():
    assert GridSearch(BOX, step=[7.5, 0.35]).counts == (5, 3)
    assert GridSearch(BOX, max_evals=1000).counts == (31, 31)
    assert GridSearch(BOX, max_iters=1).counts == (33, 33)
    assert GridSearch(BOX, counts=1, max_iters=1).size == 1
    with pytest.raises(ValueError, match="counts or step, not both"):
        GridSearch(BOX, counts=3, step=1.0)
    with pytest.raises(ValueError, match="counts must be"):
        GridSearch(BOX, counts=[3, 0])


def test_grid_truncated_by_budget():
    r = maximize(_f, BOX, "grid", counts=10, max_evals=55)
    assert r.nfev == 55 and r.status is Status.BUDGET_EXHAUSTED


def test_grid_sound_bound_when_complete():
    # |d f / d roll| <= 1/5, |d f / d contrast| = 1; the true max is 2.4 on the grid itself
    r = maximize(_f, BOX, "grid", counts=[31, 8], max_evals=10_000, lipschitz=[0.2, 1.0])
    half = np.array([0.5, 0.05])  # half spacings
    assert r.upper_bound == pytest.approx(2.4 + 0.2 * half[0] + 1.0 * half[1])
    assert r.verdict(2.56) is Verdict.CERTIFIED and r.verdict(2.5) is Verdict.NO_BREACH_FOUND and r.verdict(2.3) is Verdict.BREACH
    partial = maximize(_f, BOX, "grid", counts=[31, 8], max_evals=100, lipschitz=[0.2, 1.0])
    assert partial.upper_bound is None and partial.verdict(2.5) is Verdict.NO_BREACH_FOUND


def test_grid_center_out_visits_every_node_once_by_growing_distance():
    roll = ParameterBox({"roll_deg": (-3.0, 3.0)})
    r = maximize(lambda x: -np.abs(x[:, 0]), roll, "grid", counts=13, order="center-out", batch_size=4,
                 max_evals=100)
    assert r.status is Status.CONVERGED and r.nfev == 13
    assert np.allclose(np.sort(r.xs[:, 0]), np.linspace(-3, 3, 13))
    assert np.all(np.diff(np.abs(r.xs[:, 0])) >= -1e-12) and r.xs[0, 0] == 0.0
    # 2-D: normalised Chebyshev rings, each node once
    r2 = maximize(_f, BOX, "grid", counts=[5, 3], order="center-out", batch_size=64, max_evals=100)
    u = BOX.to_unit(r2.xs)
    ring = np.max(np.abs(u - 0.5), axis=1)
    assert r2.nfev == 15 and len({tuple(p) for p in np.round(u, 9)}) == 15 and np.all(np.diff(ring) >= -1e-12)
    with pytest.raises(ValueError, match="order must be one of"):
        GridSearch(BOX, counts=3, order="spiral")


def test_center_out_grid_stopped_at_a_breach_answers_every_nested_budget():
    # L breaches only beyond 7.3°: the grid stops in the batch holding ±7.5° and has seen all of ±7.25°
    roll = ParameterBox({"roll_deg": (-30.0, 30.0)})
    r = maximize(lambda x: np.where(np.abs(x[:, 0]) > 7.3, 3000.0, 10.0 + np.abs(x[:, 0])), roll, "grid",
                 counts=241, order="center-out", batch_size=8, stop_above=1000.0, max_evals=241)
    assert r.status is Status.TARGET_REACHED and r.nfev < 241 // 3
    inside = np.abs(r.xs[:, 0]) <= 7.25 + 1e-9
    assert inside.sum() == 59 and r.fs[inside].max() == pytest.approx(17.25)
