"""APGD: schedule, convergence on smooth functions, per-row failures, differentiability errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.search.apgd import APGD, apgd_checkpoints
from vbl_robust.search.api import maximize
from vbl_robust.search.result import Status
from vbl_robust.space import ParameterBox


def test_checkpoints_match_autoattack():
    assert apgd_checkpoints(100) == [22, 41, 57, 70, 80, 87, 93, 99]
    assert apgd_checkpoints(10) == [2, 3, 4, 5, 6, 7, 8, 9, 10]
    assert apgd_checkpoints(1) == [1]
    with pytest.raises(ValueError, match="n_iter"):
        apgd_checkpoints(0)


def test_reaches_interior_max_of_concave_quadratic():
    box = ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.7, 1.4), "gamma": (0.5, 2.0)})
    c = torch.tensor([4.0, 1.1, 0.8], dtype=torch.float64)
    w = torch.tensor([1.0 / 30, 1.0 / 0.7, 1.0 / 1.5], dtype=torch.float64)

    def f(x):
        return -(((x - c) * w) ** 2).sum(dim=1)

    r = maximize(f, box, "apgd", max_evals=404, n_restarts=4)
    assert r.nfev == 404 and r.status is Status.BUDGET_EXHAUSTED
    assert r.fun > -1e-5 and np.allclose(r.x, c.numpy(), atol=0.01 * box.width)


def test_reaches_corner_max_of_linear_function():
    box = ParameterBox({"a": (-1.0, 2.0), "b": (0.0, 3.0)})
    r = maximize(lambda x: x[:, 0] - 2.0 * x[:, 1], box, "apgd", max_evals=40, n_restarts=2)
    assert np.array_equal(r.x, [2.0, 0.0])  # sign steps of size 1 reach the corner exactly


def test_smooth_multimodal_1d_from_several_restarts():
    box = ParameterBox({"roll_deg": (-10.0, 10.0)})

    def f(x):  # local maxima every 2pi/1.3; the global one near 6.22 (value 1.438)
        a = x[:, 0]
        return torch.sin(1.3 * a) + 0.7 * torch.exp(-((a - 7.5) ** 2) / 4)

    grid = np.linspace(-10, 10, 200001)
    true = np.max(np.sin(1.3 * grid) + 0.7 * np.exp(-((grid - 7.5) ** 2) / 4))
    r = maximize(f, box, "apgd", max_evals=8 * 101, n_restarts=8, seed=0)
    assert r.fun >= true - 1e-4


def test_step_halves_and_restarts_at_checkpoints():
    box = ParameterBox({"a": (0.0, 1.0)})
    opt = APGD(box, n_iter=100, n_restarts=3, max_evals=303)
    while len(x := opt.ask()):
        xt = torch.tensor(x, requires_grad=True)
        y = -((xt[:, 0] - 0.3) ** 2)
        (g,) = torch.autograd.grad(y.sum(), xt)
        opt.tell(x, y.detach().numpy(), grad=g.numpy())
    # on a concave function sign steps overshoot and oscillate: eta halves at checkpoints
    assert np.all(opt._eta < 1.0) and np.all(opt._eta >= 2.0**-8)
    assert abs(opt.result().x[0] - 0.3) < 1e-3


def test_non_finite_gradient_stops_that_restart_only():
    box = ParameterBox({"a": (0.0, 1.0), "b": (0.0, 1.0)})

    class NanGradBelowHalf(torch.autograd.Function):  # identity whose gradient is NaN where a <= 0.5
        @staticmethod
        def forward(ctx, a):
            ctx.save_for_backward(a)
            return a.clone()

        @staticmethod
        def backward(ctx, grad):
            (a,) = ctx.saved_tensors
            return torch.where(a <= 0.5, torch.full_like(grad, float("nan")), grad)

    def f(x):  # value finite everywhere, max 1 at (1, 0.2)
        return NanGradBelowHalf.apply(x[:, 0]) - (x[:, 1] - 0.2) ** 2

    r = maximize(f, box, "apgd", max_evals=200, n_restarts=8, seed=1)
    assert r.status is Status.BUDGET_EXHAUSTED and r.nfev == 200
    assert r.trace[-1].extra["failed_rows"] > 0
    assert r.fun > 0.999  # rows that started with a > 0.5 climbed to a = 1


def test_nan_values_stop_rows_and_new_rounds_start():
    box = ParameterBox({"a": (0.0, 1.0)})
    r = maximize(lambda x: x[:, 0] * float("nan"), box, "apgd", max_evals=20, n_restarts=2)
    assert r.n_failed == 20 and r.trace[-1].extra["round"] == 10


def test_clear_error_without_gradients():
    box = ParameterBox({"a": (0.0, 1.0)})
    with pytest.raises(ValueError, match="torch-differentiable"):
        maximize(lambda x: np.sin(np.asarray(x)[:, 0]), box, "apgd", max_evals=10)
    with pytest.raises(ValueError, match="no gradient"):
        maximize(lambda x: x[:, 0].detach() * 2, box, "apgd", max_evals=10)
    with pytest.raises(ValueError, match="returned ndarray"):
        maximize(lambda x: x[:, 0].detach().numpy(), box, "apgd", max_evals=10)
    with pytest.raises(ValueError, match="needs grad="):
        opt = APGD(box, max_evals=5)
        x = opt.ask()
        opt.tell(x, x[:, 0])
    with pytest.raises(ValueError, match="rho"):
        APGD(box, rho=1.5)


def test_n_iter_shrinks_to_fit_the_budget():
    box = ParameterBox({"a": (0.0, 1.0)})
    assert (APGD(box, max_evals=50, n_restarts=4).n_iter, APGD(box, max_evals=50).n_restarts) == (11, 4)
    assert APGD(box, max_evals=3, n_restarts=4).n_restarts == 1
    assert APGD(box, max_seconds=1.0).n_iter == 100
