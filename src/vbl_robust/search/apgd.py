"""APGD (Croce & Hein, ICML 2020) on the normalised box, as an ask/tell search with batched restarts.

The objective must give gradients: ``tell(x, values, grad=...)`` with ``grad`` the gradient of each value
w.r.t. its real-unit point (:func:`~vbl_robust.search.maximize` obtains it with torch autograd). Only its sign is
used, in the unit cube (real = lower + u * width with width > 0, so signs agree).

Schedule (AutoAttack's ``autopgd_base.py``, our own code):

* A *round* runs ``n_restarts`` rows in parallel (one batch per step) for ``n_iter`` steps from uniform random
  starts (``torch.Generator`` seeded with ``seed``); rounds repeat until a budget stops the search.
* Step: ``z = clamp(x_k + η sign ∇f(x_k))``, ``x_{k+1} = clamp(x_k + a (z - x_k) + (1 - a)(x_k - x_{k-1}))``,
  ``a = 1`` on a row's first step (and the first after a restart), ``momentum = 0.75`` otherwise; initial
  ``η = step0 = 1.0`` (the box width in the unit cube, AutoAttack's 2ε), one η per row.
* Checkpoints (:func:`apgd_checkpoints`; N = 100 → 22, 41, 57, 70, 80, 87, 93, 99): a row halves η and restarts
  from its best point (with the gradient stored there) if (1) at most ``rho`` of its steps since the previous
  checkpoint increased f, or (2) η was not halved at the previous checkpoint and its best value has not improved.
* A row whose value or gradient is NaN/inf stops for the rest of its round (counted in ``extra``).

With ``max_evals`` and no explicit ``n_iter``, ``n_iter`` shrinks so that one round fits the budget.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ..space import ParameterBox
from .base import Optimizer

N_ITER = 100
MOMENTUM = 0.75
RHO = 0.75
FIRST_CHECKPOINT = 0.22  # fraction of n_iter before the first checkpoint
INTERVAL_DECREASE = 0.03  # each checkpoint interval is this fraction shorter than the previous …
MIN_INTERVAL = 0.06  # … but never shorter than this fraction


def apgd_checkpoints(n_iter: int) -> list[int]:
    """Step counts (1-based) after which APGD checks its step size, with AutoAttack's integer rounding.

    >>> apgd_checkpoints(100)
    [22, 41, 57, 70, 80, 87, 93, 99]
    """
    if n_iter < 1:
        raise ValueError(f"n_iter must be >= 1, got {n_iter}")
    interval = max(int(FIRST_CHECKPOINT * n_iter), 1)
    decrease = max(int(INTERVAL_DECREASE * n_iter), 1)
    shortest = max(int(MIN_INTERVAL * n_iter), 1)
    out, at = [], interval
    while at <= n_iter:
        out.append(at)
        interval = max(interval - decrease, shortest)
        at += interval
    return out


class APGD(Optimizer):
    """Auto-PGD maximisation with batched restarts (see the module docstring).

    Args (besides the :class:`Optimizer` budgets):
        n_iter: steps per round (None: 100, shrunk to fit ``max_evals``).
        n_restarts: rows run in parallel per round.
        step0: initial step in the unit cube.
        momentum, rho: AutoAttack's 0.75 and 0.75.
    """

    name: ClassVar[str] = "apgd"
    label: ClassVar[str] = "APGD"
    needs_gradient: ClassVar[bool] = True
    anytime: ClassVar[bool] = False  # n_iter (the step-size schedule) is fitted to max_evals

    def __init__(
        self,
        box: ParameterBox,
        *,
        n_iter: int | None = None,
        n_restarts: int = 4,
        step0: float = 1.0,
        momentum: float = MOMENTUM,
        rho: float = RHO,
        **budget: Any,
    ):
        super().__init__(box, **budget)
        for name, v, lo, hi in (("step0", step0, 0.0, math.inf), ("momentum", momentum, 0.0, 1.0), ("rho", rho, 0.0, 1.0)):
            if not (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and lo < v <= hi):
                raise ValueError(f"{name} must be a number in ({lo}, {hi}], got {v!r}")
        for name, v in (("n_iter", n_iter), ("n_restarts", n_restarts)):
            if v is not None and (not isinstance(v, int | np.integer) or isinstance(v, bool) or v < 1):
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        rows, steps = int(n_restarts), N_ITER if n_iter is None else int(n_iter)
        if n_iter is None and self.max_evals is not None:
            if self.max_evals < 2 * rows:
                rows = max(1, self.max_evals // 2)
            steps = max(1, min(steps, self.max_evals // rows - 1))
        self.n_restarts, self.n_iter = rows, steps
        self.step0, self.momentum, self.rho = float(step0), float(momentum), float(rho)
        self.checkpoints = set(apgd_checkpoints(steps))
        import torch

        self._gen = torch.Generator().manual_seed(self.seed)
        self.round = 0
        self.n_failed_rows = 0
        self._start_round()

    def _start_round(self) -> None:
        import torch

        r, d = self.n_restarts, self.dim
        self.round += 1
        self._x = torch.rand((r, d), generator=self._gen, dtype=torch.float64).numpy()
        self._x_prev = self._x.copy()
        self._grad = np.zeros((r, d))
        self._f = np.full(r, -np.inf)
        self._eta = np.full(r, self.step0)
        self._best_u = self._x.copy()
        self._best_f = np.full(r, -np.inf)
        self._best_grad = np.zeros((r, d))
        self._first = np.ones(r, dtype=bool)  # next step uses a = 1
        self._active = np.ones(r, dtype=bool)
        self._step = 0  # steps taken this round; 0 = the starts are not evaluated yet
        self._increases = np.zeros(r, dtype=np.int64)
        self._since = 0  # steps since the last checkpoint
        self._best_at_check = np.full(r, -np.inf)
        self._reduced_last = np.zeros(r, dtype=bool)
        self._rows: np.ndarray = np.zeros(0, dtype=np.int64)

    def _ask(self, remaining: int | None) -> np.ndarray:
        if self._step > self.n_iter or not self._active.any():
            self._start_round()
        rows = np.flatnonzero(self._active)
        if remaining is not None and len(rows) > remaining:
            self._active[rows[remaining:]] = False
            rows = rows[:remaining]
        self._rows = rows
        if self._step == 0:
            return self._x[rows]
        x, g, xp = self._x[rows], self._grad[rows], self._x_prev[rows]
        a = np.where(self._first[rows], 1.0, self.momentum)[:, None]
        z = np.clip(x + self._eta[rows, None] * np.sign(g), 0.0, 1.0)
        new = np.clip(x + a * (z - x) + (1.0 - a) * (x - xp), 0.0, 1.0)
        self._x_prev[rows] = x
        self._x[rows] = new
        self._first[rows] = False
        return new

    def _tell(self, u: np.ndarray, values: np.ndarray, failed: np.ndarray, grad: np.ndarray | None) -> dict[str, Any]:
        rows = self._rows
        g_unit = grad * self.box.width  # chain rule: d f / d u = d f / d x * width
        bad = failed | ~np.all(np.isfinite(g_unit), axis=1)
        if bad.any():
            self._active[rows[bad]] = False
            self.n_failed_rows += int(bad.sum())
        ok_rows = rows[~bad]
        v = values[~bad]
        if self._step > 0:
            self._increases[ok_rows] += v > self._f[ok_rows]
        self._f[ok_rows] = v
        self._grad[ok_rows] = g_unit[~bad]
        better = v > self._best_f[ok_rows]
        up = ok_rows[better]
        self._best_f[up] = v[better]
        self._best_u[up] = self._x[up]
        self._best_grad[up] = self._grad[up]
        if self._step == 0:
            self._best_at_check[:] = self._best_f
        else:
            self._since += 1
            if self._step in self.checkpoints:
                self._checkpoint()
        self._step += 1
        return {"extra": {"round": self.round, "step": self._step - 1, "active": int(self._active.sum()),
                          "eta_min": float(self._eta.min()), "failed_rows": self.n_failed_rows}}

    def _checkpoint(self) -> None:
        act = self._active
        oscillating = self._increases <= self.rho * self._since
        stalled = ~self._reduced_last & (self._best_at_check >= self._best_f)
        halve = act & (oscillating | stalled)
        self._eta[halve] /= 2.0
        self._x[halve] = self._best_u[halve]
        self._x_prev[halve] = self._best_u[halve]
        self._grad[halve] = self._best_grad[halve]
        self._f[halve] = self._best_f[halve]
        self._first[halve] = True
        self._reduced_last = halve
        self._best_at_check = self._best_f.copy()
        self._increases[:] = 0
        self._since = 0
