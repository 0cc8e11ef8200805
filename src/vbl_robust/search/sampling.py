"""Sampling baselines: uniform random search, scrambled Sobol, and the dense grid (ground truth)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from scipy.stats import qmc

from ..constants import MAX_GRID_POINTS
from ..space import ParameterBox
from .base import Optimizer
from .cells import Cells
from .result import Status

#: Points per dimension of a grid when neither counts, step nor max_evals say otherwise.
DEFAULT_GRID_COUNT = 33


def _check_batch(batch_size: Any) -> int:
    if not isinstance(batch_size, int | np.integer) or isinstance(batch_size, bool) or batch_size < 1:
        raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    return int(batch_size)


class _Batched(Optimizer):
    """Draws ``min(batch_size, evaluations left)`` points per iteration from ``_draw``; nothing to learn."""

    def __init__(self, box: ParameterBox, *, batch_size: int = 64, **budget: Any):
        super().__init__(box, **budget)
        self.batch_size = _check_batch(batch_size)

    def _ask(self, remaining: int | None) -> np.ndarray:
        n = self.batch_size if remaining is None else min(self.batch_size, remaining)
        return self._draw(n)

    def _draw(self, n: int) -> np.ndarray:
        raise NotImplementedError

    def _tell(self, u: np.ndarray, values: np.ndarray, failed: np.ndarray, grad: np.ndarray | None) -> None:
        return None


class RandomSearch(_Batched):
    """Uniform random search (``numpy.random.default_rng(seed)``), ``batch_size`` points per iteration."""

    name: ClassVar[str] = "random"
    label: ClassVar[str] = "Random"
    iid_uniform: ClassVar[bool] = True

    def __init__(self, box: ParameterBox, *, batch_size: int = 64, **budget: Any):
        super().__init__(box, batch_size=batch_size, **budget)
        self._rng = np.random.default_rng(self.seed)

    def _draw(self, n: int) -> np.ndarray:
        return self._rng.random((n, self.dim))


class SobolSearch(_Batched):
    """Scrambled Sobol' sequence (``scipy.stats.qmc.Sobol``, scrambled with the seed), read in order in batches
    of ``batch_size`` (powers of two keep its balance properties)."""

    name: ClassVar[str] = "sobol"
    label: ClassVar[str] = "Sobol"

    def __init__(self, box: ParameterBox, *, batch_size: int = 64, **budget: Any):
        super().__init__(box, batch_size=batch_size, **budget)
        try:
            self._sampler = qmc.Sobol(self.dim, scramble=True, rng=np.random.default_rng(self.seed))
        except TypeError:  # scipy < 1.15 names it seed
            self._sampler = qmc.Sobol(self.dim, scramble=True, seed=np.random.default_rng(self.seed))

    def _draw(self, n: int) -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "balance properties … power of 2": we read in order
            return self._sampler.random(n)


#: Orders in which a grid can be evaluated.
GRID_ORDERS = ("c", "center-out")


class GridSearch(Optimizer):
    """Dense lattice including the box's corners, evaluated in batches.

    Args:
        counts: points per dimension (an int for all, or one per parameter, each >= 1; 1 = the centre).
        step: alternatively the spacing in real units (a number or one per parameter); counts become
            ``floor(width / step) + 1``.
        batch_size: points per iteration.
        order: ``"c"`` — C order (last parameter fastest); ``"center-out"`` — by growing normalised Chebyshev
            distance from the box centre (ties in C order). With ``stop_above``, a centre-out grid that stops at
            its first breach at normalised radius r* has evaluated every node of each centred sub-box of radius
            < r*: those sub-boxes' worst values are exact and every larger one holds the breach. That answers
            "is there a breach within ±b?" for all nested budgets b at once, at the cost of the breach radius
            instead of the whole grid.

    Without counts or step: the largest equal count whose lattice fits ``max_evals``, else 33 per dimension.
    The grid stops with CONVERGED when complete; with ``lipschitz`` its cells (half a spacing around each node)
    give a sound ``upper_bound`` once complete.
    """

    name: ClassVar[str] = "grid"
    label: ClassVar[str] = "grid"
    covers: ClassVar[bool] = True

    def __init__(
        self,
        box: ParameterBox,
        *,
        counts: int | Sequence[int] | None = None,
        step: float | Sequence[float] | None = None,
        batch_size: int = 256,
        order: str = "c",
        **budget: Any,
    ):
        super().__init__(box, **budget)
        self.batch_size = _check_batch(batch_size)
        if order not in GRID_ORDERS:
            raise ValueError(f"grid: order must be one of {', '.join(GRID_ORDERS)}, got {order!r}")
        self.order = order
        d = self.dim
        if counts is not None and step is not None:
            raise ValueError(f"grid: give counts or step, not both (counts={counts!r}, step={step!r})")
        if counts is not None:
            c = np.broadcast_to(np.asarray(counts), (d,)) if np.ndim(counts) == 0 else np.asarray(counts)
            if c.shape != (d,) or not all(isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 1 for v in c.tolist()):
                raise ValueError(f"grid: counts must be an integer >= 1 or {d} of them, got {counts!r}")
            self.counts = tuple(int(v) for v in c)
        elif step is not None:
            s = np.broadcast_to(np.asarray(step, dtype=np.float64), (d,)) if np.ndim(step) == 0 else np.asarray(step, dtype=np.float64)
            if s.shape != (d,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
                raise ValueError(f"grid: step must be a number > 0 or {d} of them, got {step!r}")
            self.counts = tuple(int(math.floor(w / v + 1e-9)) + 1 for w, v in zip(box.width, s, strict=True))
        elif self.max_evals is not None:
            k = max(1, int(math.floor(self.max_evals ** (1.0 / d) + 1e-9)))
            while k > 1 and k**d > self.max_evals:
                k -= 1
            self.counts = (k,) * d
        else:
            self.counts = (DEFAULT_GRID_COUNT,) * d
        self.size = int(np.prod([float(c) for c in self.counts]))
        if self.size > MAX_GRID_POINTS:
            raise ValueError(f"grid: {' × '.join(map(str, self.counts))} = {self.size} points exceeds the bound of "
                             f"{MAX_GRID_POINTS} (a coarser step or fewer counts)")
        self._axes = [np.full(1, 0.5) if n == 1 else np.linspace(0.0, 1.0, n) for n in self.counts]
        self._next = 0
        self._perm: np.ndarray | None = None
        if order == "center-out" and self.size > 1:
            idx = np.indices(self.counts).reshape(d, -1)
            radius = np.max([np.abs(ax[i] - 0.5) for ax, i in zip(self._axes, idx, strict=True)], axis=0)
            # rounding makes nodes at the same distance tie exactly (linspace is not symmetric to the last bit)
            self._perm = np.argsort(np.round(radius, 12), kind="stable")

    def _ask(self, remaining: int | None) -> np.ndarray:
        n = min(self.batch_size, self.size - self._next)
        if remaining is not None:
            n = min(n, remaining)
        if n <= 0:
            self._finish(Status.CONVERGED, f"grid of {self.size} points complete")
            return np.zeros((0, self.dim))
        flat = np.arange(self._next, self._next + n)
        if self._perm is not None:
            flat = self._perm[flat]
        idx = np.unravel_index(flat, self.counts)
        self._next += n
        return np.stack([ax[i] for ax, i in zip(self._axes, idx, strict=True)], axis=1)

    def _tell(self, u: np.ndarray, values: np.ndarray, failed: np.ndarray, grad: np.ndarray | None) -> None:
        return None

    def _complete(self) -> str | None:
        return f"grid of {self.size} points complete" if self._next >= self.size else None

    def _half_spacing(self) -> np.ndarray:
        return np.array([0.5 if n == 1 else 0.5 / (n - 1) for n in self.counts])

    def _node_units(self, flat: np.ndarray) -> np.ndarray:
        idx = np.unravel_index(flat, self.counts)
        return np.stack([ax[i] for ax, i in zip(self._axes, idx, strict=True)], axis=1).reshape(-1, self.dim)

    def cells(self) -> Cells | None:
        """One cell per node of the lattice (see :meth:`Optimizer.cells`), in evaluation order, then the nodes not
        evaluated yet (``failed=True``, value NaN); None before the first batch is told. ``lipschitz_estimate``:
        the largest slope between evaluated neighbouring nodes (unit cube), None when no two neighbours have
        finite values."""
        if self.nfev == 0:
            return None
        order = self._perm if self._perm is not None else np.arange(self.size)
        u = self._node_units(order)
        h = self._half_spacing()
        n = min(self.nfev, self.size)
        values = np.full(self.size, np.nan)
        values[:n] = np.concatenate(self._fs)[:n]
        failed = ~np.isfinite(values)
        values[failed] = np.nan
        lo, hi = np.clip(u - h, 0.0, 1.0), np.clip(u + h, 0.0, 1.0)
        box = self.box
        centers = box.from_unit(u)
        centers[:n] = np.concatenate(self._xs)[:n]  # the told points, bit for bit
        # the radius of a clipped cell is the distance from its node to its far side: h on every axis
        return Cells(
            box=box, centers=centers, half_widths=np.broadcast_to(h * box.width, (self.size, self.dim)),
            lower=box.from_unit(lo), upper=box.from_unit(hi), values=values, failed=failed,
            fractions=np.prod(hi - lo, axis=1), method=self.name, lipschitz_estimate=self._neighbour_slope(order, values),
        )

    def _neighbour_slope(self, order: np.ndarray, values: np.ndarray) -> float | None:
        grid = np.full(self.size, np.nan)
        grid[order] = values
        grid = grid.reshape(self.counts)
        best = None
        for i, n in enumerate(self.counts):
            if n < 2:
                continue
            with np.errstate(invalid="ignore"):
                s = np.abs(np.diff(grid, axis=i)) * (n - 1)
            s = s[np.isfinite(s)]
            if s.size:
                best = max(best or 0.0, float(s.max()))
        return best

    def _cover(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self._next < self.size or self.nfev < self.size:
            return None
        half = np.array([0.5 if n == 1 else 0.5 / (n - 1) for n in self.counts])
        values = np.concatenate(self._fs)[: self.size]
        return values, np.broadcast_to(half, (self.size, self.dim))
