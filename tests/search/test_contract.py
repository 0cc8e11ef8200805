"""One contract over every registered method: bounds, budgets, determinism, failures, stop_above, best."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import vbl_robust.search.base as base_module
from vbl_robust.constants import Verdict
from vbl_robust.constants import Verdict as SearchVerdict
from vbl_robust.search.api import METHODS, maximize, method_options
from vbl_robust.search.evaluations import NON_FINITE, Evaluations
from vbl_robust.search.result import SearchResult, Status
from vbl_robust.space import ParameterBox

from .conftest import bumpy

ALL = sorted(METHODS)


@pytest.mark.parametrize("method", ALL)
def test_stays_in_bounds_and_best_is_best_told(method, box2):
    r = maximize(bumpy, box2, method, max_evals=150)
    assert r.xs.shape == (r.nfev, 2) and r.fs.shape == (r.nfev,)
    assert box2.contains(r.xs).all()
    i = int(np.argmax(r.fs))
    assert r.fun == r.fs[i] and np.array_equal(r.x, r.xs[i])
    assert r.method == method and r.names == box2.names
    assert [row.iteration for row in r.trace] == list(range(1, r.nit + 1))
    assert [row.nfev for row in r.trace] == list(np.cumsum([row.batch_size for row in r.trace]))
    assert r.trace[-1].best_value == r.fun


@pytest.mark.parametrize("method", ALL)
@pytest.mark.parametrize("budget", [1, 7, 60])
def test_never_exceeds_max_evals(method, budget, box2):
    r = maximize(bumpy, box2, method, max_evals=budget)
    assert 1 <= r.nfev <= budget
    assert r.status in (Status.BUDGET_EXHAUSTED, Status.CONVERGED)
    assert "max_evals" in r.message or r.status is Status.CONVERGED


@pytest.mark.parametrize("method", ALL)
def test_honours_max_iters(method, box2):
    r = maximize(bumpy, box2, method, max_iters=3)
    assert r.nit == 3 and r.status is Status.BUDGET_EXHAUSTED and "max_iters=3" in r.message


@pytest.mark.parametrize("method", ALL)
def test_honours_max_seconds_between_chunks(method, box2, monkeypatch):
    clock = {"t": 0.0}
    starts = []
    monkeypatch.setattr(base_module, "_clock", lambda: clock["t"])

    def slow(x):  # every objective call takes one (fake) second, whatever its size
        starts.append(clock["t"])
        clock["t"] += 1.0
        return bumpy(x)

    r = maximize(slow, box2, method, max_seconds=3.5)
    assert r.status is Status.TIME_OUT and "max_seconds=3.5" in r.message
    # no chunk starts after the budget; the one running when it ran out (3 s → 4 s) is not counted
    assert max(starts) < 3.5 and len(starts) == 4
    assert r.nfev == 3 and np.array_equal(r.times, [1.0, 2.0, 3.0]) and r.elapsed == 3.0


@pytest.mark.parametrize("method", ALL)
def test_same_seed_same_run(method, box2):
    a = maximize(bumpy, box2, method, max_evals=120, seed=3)
    b = maximize(bumpy, box2, method, max_evals=120, seed=3)
    assert np.array_equal(a.xs, b.xs) and np.array_equal(a.fs, b.fs)
    assert a.fun == b.fun and a.nfev == b.nfev and a.nit == b.nit


@pytest.mark.parametrize("method", ["random", "sobol", "apgd"])
def test_seed_changes_random_methods(method, box2):
    a = maximize(bumpy, box2, method, max_evals=40, seed=1)
    b = maximize(bumpy, box2, method, max_evals=40, seed=2)
    assert not np.array_equal(a.xs, b.xs)


def _holey(x):
    """bumpy, but NaN where roll < 0 and +inf where roll > 4.5 (failed evaluations)."""
    y = bumpy(x)
    if isinstance(y, torch.Tensor):
        y = torch.where(x[:, 0] < 0, torch.full_like(y, float("nan")), y)
        return torch.where(x[:, 0] > 4.5, torch.full_like(y, float("inf")), y)
    y = np.where(x[:, 0] < 0, np.nan, y)
    return np.where(x[:, 0] > 4.5, np.inf, y)


@pytest.mark.parametrize("method", ALL)
def test_nan_and_inf_are_failed_evaluations(method, box2):
    r = maximize(_holey, box2, method, max_evals=200)
    failed = ~np.isfinite(r.fs)
    assert r.n_failed == failed.sum() > 0
    assert np.isfinite(r.fun) and r.fun == r.fs[~failed].max()
    assert 0 <= r.x[0] <= 4.5
    assert r.trace[-1].n_failed == r.n_failed


PENALTY = 50.0


def _penalised(x):
    """bumpy, but failed (reason "no_detection", a finite penalty) where roll < -1, as the pipeline does."""
    y = bumpy(x)
    xp = torch if isinstance(y, torch.Tensor) else np
    lost = x[:, 0] < -1.0
    y = xp.where(lost, xp.full_like(y, PENALTY), y)
    return Evaluations(y, tuple("no_detection" if v else "" for v in lost.tolist()))


@pytest.mark.parametrize("method", ALL)
def test_failure_reasons_are_recorded_and_the_search_is_unchanged(method, box2):
    r = maximize(_penalised, box2, method, max_evals=120, seed=1)

    def plain(x):
        return _penalised(x).values

    same = maximize(plain, box2, method, max_evals=120, seed=1)
    assert np.array_equal(r.xs, same.xs) and np.array_equal(r.fs, same.fs) and r.fun == same.fun  # same search
    lost = r.xs[:, 0] < -1.0
    assert r.reasons == tuple("no_detection" if v else "" for v in lost)
    assert r.n_failed == lost.sum() == r.trace[-1].n_failed and same.n_failed == 0 and same.reasons == ("",) * same.nfev
    assert r.failures == ({"no_detection": int(lost.sum())} if lost.any() else {})
    assert r.x_reason == ("no_detection" if r.fun == PENALTY else "")  # the penalty can be the worst case
    assert SearchResult.from_dict(json.loads(json.dumps(r.to_dict()))).reasons == r.reasons


@pytest.mark.parametrize("method", ALL)
def test_non_finite_values_without_a_reason_are_recorded_as_non_finite(method, box2):
    r = maximize(_holey, box2, method, max_evals=60)
    assert r.reasons == tuple("" if np.isfinite(v) else NON_FINITE for v in r.fs)
    assert r.failures == {NON_FINITE: r.n_failed}


def test_tell_accepts_evaluations_and_checks_their_length(box2):
    opt = METHODS["random"](box2, max_evals=10, batch_size=5)
    x = opt.ask()
    with pytest.raises(ValueError, match="5 reasons for 4 values"):
        Evaluations(np.zeros(4), ("",) * 5)
    opt.tell(x, Evaluations(bumpy(x), ("", "pnp_failed", "", "", "")))
    assert opt.result().failures == {"pnp_failed": 1} and opt.result().reasons[1] == "pnp_failed"


def test_search_verdict_is_the_package_verdict():
    assert SearchVerdict is Verdict and Verdict.NO_BREACH_FOUND.value == "no breach found"


@pytest.mark.parametrize("method", ALL)
def test_all_failed_gives_no_best(method, box2):
    def nan(x):
        return x[:, 0] * float("nan")

    r = maximize(nan, box2, method, max_evals=30)
    assert r.x is None and np.isnan(r.fun) and not r.success and r.n_failed == r.nfev > 0


@pytest.mark.parametrize("method", ALL)
def test_stop_above_record_ends_at_the_first_breach_whatever_the_chunk(method, box2):
    threshold = 1.2
    runs = {}
    for chunk in (1, 3, 32, 10_000):
        evaluated = []

        def f(x, evaluated=evaluated):
            evaluated.append(len(x))
            return bumpy(x)

        r = maximize(f, box2, method, max_evals=3000, stop_above=threshold, chunk_size=chunk)
        assert r.status is Status.TARGET_REACHED and r.fun == r.fs[-1] > threshold
        assert np.all(r.fs[:-1] <= threshold)  # the record ends at the first breach
        # evaluated beyond the breach: at most the rest of the chunk holding it (the method's gradient steps and
        # the batches before are whole, so everything before the breach was needed)
        assert r.nfev <= sum(evaluated) <= r.nfev + chunk - 1
        assert max(evaluated) <= chunk
        runs[chunk] = r
    first = runs[1]
    for r in runs.values():  # the chunk size changes what is computed, never the result
        assert np.array_equal(r.xs, first.xs) and np.array_equal(r.fs, first.fs) and r.nit == first.nit


@pytest.mark.parametrize("method", ALL)
def test_a_breach_inside_a_told_batch_cuts_the_record_there(method, box2):
    opt = METHODS[method](box2, max_evals=500, stop_above=0.5)
    x = opt.ask()
    while len(x) < 3:  # a batch of at least 3 points
        opt.tell(x, np.zeros(len(x)), grad=np.zeros_like(x))
        x = opt.ask()
    values = np.zeros(len(x))
    values[1], values[2] = 0.7, 0.9  # the first breach is the second point
    opt.tell(x, values, grad=np.zeros_like(x))
    r = opt.result()
    assert r.status is Status.TARGET_REACHED and r.fun == 0.7 and np.array_equal(r.x, x[1])
    assert np.array_equal(r.xs[-2:], x[:2]) and r.trace[-1].batch_size == 2 and r.trace[-1].extra["partial"]
    assert len(opt.ask()) == 0


@pytest.mark.parametrize("method", ALL)
def test_ask_tell_by_hand_and_misuse(method, box2):
    opt = METHODS[method](box2, max_evals=2000)
    with pytest.raises(RuntimeError, match="no batch pending"):
        opt.tell(np.zeros((1, 2)), np.zeros(1))
    x = opt.ask()
    with pytest.raises(RuntimeError, match="not told"):
        opt.ask()
    with pytest.raises(ValueError, match="batch returned by the last ask"):
        opt.tell(x + 1.0, np.zeros(len(x)))
    with pytest.raises(ValueError, match="values must have shape"):
        opt.tell(x, np.zeros(len(x) + 1), grad=np.zeros_like(x))
    opt.tell(x, bumpy(x), grad=np.ones_like(x))
    assert opt.result().status is Status.RUNNING and opt.nfev == len(x)
    opt.stop()
    assert opt.result().status is Status.STOPPED and len(opt.ask()) == 0


@pytest.mark.parametrize("method", ALL)
def test_result_to_dict_is_json_and_round_trips(method, box2):
    r = maximize(_holey, box2, method, max_evals=40)
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    back = SearchResult.from_dict(d)
    assert back.nfev == r.nfev and back.status is r.status and back.fun == r.fun
    assert np.array_equal(back.xs, r.xs) and np.array_equal(np.isfinite(back.fs), np.isfinite(r.fs))
    assert back.to_dict() == d


def test_callback_can_stop(box2):
    seen = []
    r = maximize(bumpy, box2, "random", max_evals=1000, batch_size=10, callback=lambda row: seen.append(row) or len(seen) == 3)
    assert r.status is Status.STOPPED and r.nit == 3 and r.nfev == 30 and seen[-1].nfev == 30


def test_user_errors_name_the_argument(box2):
    with pytest.raises(ValueError, match="at least one budget"):
        maximize(bumpy, box2, "direct")
    with pytest.raises(ValueError, match="unknown search method 'nope'"):
        maximize(bumpy, box2, "nope", max_evals=10)
    with pytest.raises(ValueError, match=r"no option\(s\) \['alfa'\]"):
        maximize(bumpy, box2, "georobust", max_evals=10, alfa=2)
    with pytest.raises(ValueError, match="max_evals must be an integer >= 1"):
        maximize(bumpy, box2, "direct", max_evals=0)
    with pytest.raises(ValueError, match="max_seconds"):
        maximize(bumpy, box2, "direct", max_seconds=-1.0)
    with pytest.raises(ValueError, match="must return shape"):
        maximize(lambda x: bumpy(x)[:, None], box2, "random", max_evals=10)
    with pytest.raises(ValueError, match="ParameterBox"):
        maximize(bumpy, {"a": (0, 1)}, "random", max_evals=10)
    assert "alpha" in method_options("georobust") and "counts" in method_options("grid")


def test_plain_numpy_function_in_real_units():
    r = maximize(lambda x: -((x[:, 0] - 3.0) ** 2), ParameterBox({"a": (-10, 10)}), method="direct", max_evals=2000)
    assert abs(r.x[0] - 3.0) < 1e-3 and r.nfev <= 2000
    assert r.x_dict() == {"a": float(r.x[0])}


def test_gradient_methods_call_the_objective_with_a_tensor_the_others_with_an_array():
    """One callable serves both kinds of method (as the pipeline's objectives do): the type of θ picks the path."""
    import torch

    from vbl_robust.search.api import maximize
    from vbl_robust.space import ParameterBox

    seen = []

    def f(x):
        seen.append(type(x))
        if isinstance(x, torch.Tensor):
            assert x.requires_grad
            return -((x - 0.25) ** 2).sum(dim=1)
        return -((x - 0.25) ** 2).sum(axis=1)

    box = ParameterBox({"a": (-1, 1)})
    r = maximize(f, box, "apgd", max_evals=60, seed=0)
    assert abs(float(r.x[0]) - 0.25) < 1e-2 and set(seen) == {torch.Tensor}
    seen.clear()
    maximize(f, box, "direct", max_evals=30)
    assert set(seen) == {np.ndarray}


def test_every_method_names_and_labels_itself_once():
    """The registry key is the class's ``name``; its display label (figures, reports) lives on the class too."""
    from vbl_robust.report.figure_style import style
    from vbl_robust.search.api import METHODS

    labels = set()
    for key, cls in METHODS.items():
        assert cls.name == key and cls.label and style(key)["label"] == cls.label
        labels.add(cls.label)
    assert len(labels) == len(METHODS)
