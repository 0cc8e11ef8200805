"""The ask/tell core shared by every search method.

:class:`Optimizer` does the bookkeeping — budgets, best point, trace, failed evaluations — and subclasses
implement two hooks on the unit cube:

* ``_ask(remaining) -> (n, d)`` unit-cube points of the next batch (all points of one iteration), with
  ``n <= remaining`` when an evaluation budget is set; an empty batch means "nothing left" (the subclass may
  call :meth:`Optimizer._finish` first to say why).
* ``_tell(u, values, failed, grad)`` with the batch's unit-cube points, raw values, a mask of the values the
  method cannot use (NaN/±inf) and, for gradient methods, the gradient w.r.t. the *real-unit* point.

Failures: :meth:`Optimizer.tell` takes plain values or :class:`~vbl_robust.search.evaluations.Evaluations`
(values + failure reasons). The method sees the values only, so a point failed with a finite penalty is
searched like any other; the bookkeeping records every point's reason and counts failures (``n_failed``).

Budgets: ``max_evals`` is never exceeded (subclasses size their batches to fit); ``max_iters`` counts batches;
``max_seconds`` is checked before every ask, and the driver (:func:`~vbl_robust.search.maximize`) evaluates a
batch in chunks and checks it between chunks too: a batch cut by the time budget is recorded with
:meth:`Optimizer.tell_partial` (its evaluated points count; the method never sees it) and the search stops. The
clock starts at the first ask, so it covers the method's own work (selection, bookkeeping) as well as the
objective. ``min_evals`` (with ``max_seconds``) defers the time stop until that many evaluations are done: one
run from which every time budget ≤ ``max_seconds`` and every evaluation budget ≤ ``min_evals`` can be read
(:mod:`~vbl_robust.search.anytime`).

Time stamps: every told point carries the time its evaluation completed (``times=`` of :meth:`tell`, default
"now"), seconds on the search's clock; :attr:`SearchResult.times` holds them in evaluation order.

``anytime`` (class attribute): True when the sequence of points a method asks for does not depend on its
budgets (the DIRECT family, random, Sobol, grid — given no ``max_evals``, which DIRECT uses to fit its last
batch and the grid to size its lattice), so a run stopped at any budget is a prefix of a longer run; False for
APGD (its step schedule is fitted to ``max_evals``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

from ..constants import Verdict
from ..space import ParameterBox
from .bounds import check_lipschitz, sound_upper_bound
from .cells import Cells
from .evaluations import Evaluations, recorded_reasons, split
from .result import PARTIAL, SearchResult, Status, TraceRow, verdict_for

logger = logging.getLogger(__name__)
#: The clocks a search can run on: wall time, or the CPU seconds of this process (all its threads), which other
#: work on the machine does not move — the clock to use for time budgets on a shared CPU.
CLOCKS = {"wall": time.perf_counter, "process": time.process_time}
_clock = time.perf_counter  # module-level so tests can drive the clock (see use_clock)


@contextlib.contextmanager
def use_clock(name: str) -> Iterator[None]:
    """Run the searches of this process on the clock ``name`` (a key of :data:`CLOCKS`) inside the block."""
    global _clock
    if name not in CLOCKS:
        raise ValueError(f"clock must be one of {sorted(CLOCKS)}, got {name!r}")
    before, _clock = _clock, CLOCKS[name]
    try:
        yield
    finally:
        _clock = before


def _check_budget(name: str, value: float | None, *, integer: bool) -> None:
    if value is None:
        return
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= 1 if integer else (
        isinstance(value, int | float | np.number) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    )
    if not ok:
        kind = "an integer >= 1" if integer else "a finite number > 0"
        raise ValueError(f"{name} must be {kind} or None, got {value!r}")


class Optimizer:
    """Base class of the ask/tell searches (maximisation over a :class:`ParameterBox`).

    Args:
        box: the search space (real units).
        max_evals: evaluation budget (exact: never exceeded), or None.
        max_iters: batch budget, or None.
        max_seconds: time budget (on the clock of :func:`use_clock`: wall time by default) checked before every batch (and by :func:`maximize` between the chunks of
            a batch), or None.
        min_evals: with ``max_seconds``: the time budget stops the search only once this many evaluations are
            done (a run that covers both a time and an evaluation budget), or None.
        stop_above: stop at the first finite value ``> stop_above`` (a breach): the points after it in its batch
            are not recorded (and, with :func:`~vbl_robust.search.maximize`, evaluated only as far as the chunk
            holding it), so a search's record ends at its first breach whatever the batch or chunk sizes.
        seed: seed of every random choice of the method.
        lipschitz, lipschitz_norm: optional Lipschitz constant of the objective in real units (see
            :mod:`vbl_robust.search.bounds`); methods that keep a cover of the box then report a sound
            ``upper_bound``.

    Usage::

        opt = Direct(box, max_evals=500)
        while len(x := opt.ask()):
            opt.tell(x, f(x))
        result = opt.result()
    """

    name: ClassVar[str] = ""
    #: The method's name in figures and reports.
    label: ClassVar[str] = ""
    needs_gradient: ClassVar[bool] = False
    #: The points asked for do not depend on the budgets (see the module docstring).
    anytime: ClassVar[bool] = True
    #: The method keeps cells that tile the box (:meth:`cells`): the DIRECT family and the grid.
    covers: ClassVar[bool] = False
    #: Its points are independent and uniform over the box, so k of them without a breach bound the breached
    #: fraction of the box (:func:`vbl_robust.stats.breach_fraction_bound`): random search only.
    iid_uniform: ClassVar[bool] = False

    def __init__(
        self,
        box: ParameterBox,
        *,
        max_evals: int | None = None,
        max_iters: int | None = None,
        max_seconds: float | None = None,
        min_evals: int | None = None,
        stop_above: float | None = None,
        seed: int = 0,
        lipschitz: float | tuple[float, ...] | None = None,
        lipschitz_norm: str = "2",
    ):
        if not isinstance(box, ParameterBox):
            raise ValueError(f"box must be a vbl_robust.ParameterBox, got {type(box).__name__}")
        _check_budget("max_evals", max_evals, integer=True)
        _check_budget("max_iters", max_iters, integer=True)
        _check_budget("max_seconds", max_seconds, integer=False)
        _check_budget("min_evals", min_evals, integer=True)
        if min_evals is not None and max_seconds is None:
            raise ValueError(f"min_evals={min_evals!r} needs max_seconds (it defers the time stop)")
        if min_evals is not None and max_evals is not None and min_evals > max_evals:
            raise ValueError(f"min_evals={min_evals!r} exceeds max_evals={max_evals!r}")
        if stop_above is not None and not (isinstance(stop_above, int | float | np.number) and not math.isnan(stop_above)):
            raise ValueError(f"stop_above must be a number or None, got {stop_above!r}")
        if not isinstance(seed, int | np.integer) or isinstance(seed, bool):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        self.box = box
        self.dim = box.dim
        self.max_evals = None if max_evals is None else int(max_evals)
        self.max_iters = None if max_iters is None else int(max_iters)
        self.max_seconds = None if max_seconds is None else float(max_seconds)
        self.min_evals = None if min_evals is None else int(min_evals)
        self.stop_above = None if stop_above is None else float(stop_above)
        self.seed = int(seed)
        self.lipschitz = check_lipschitz(lipschitz, lipschitz_norm, box.dim)
        self.lipschitz_norm = lipschitz_norm if self.lipschitz is not None else None

        self.nfev = 0
        self.nit = 0
        self.n_failed = 0
        self.status = Status.RUNNING
        self.message = "running"
        self.trace: list[TraceRow] = []
        self._xs: list[np.ndarray] = []
        self._fs: list[np.ndarray] = []
        self._reasons: list[str] = []
        self._ts: list[np.ndarray] = []
        self._best_value = math.nan
        self._best_x: np.ndarray | None = None
        self._best_reason = ""
        self._t0: float | None = None
        self._t_last = 0.0
        self._pending: tuple[np.ndarray, np.ndarray] | None = None  # (real, unit) of the last ask

    # -- public ask/tell -----------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.status is not Status.RUNNING

    def elapsed(self) -> float:
        return 0.0 if self._t0 is None else _clock() - self._t0

    def ask(self) -> np.ndarray:
        """Next batch ``(n, d)`` in real units; an empty ``(0, d)`` array once the search has stopped."""
        if self._pending is not None:
            raise RuntimeError(f"{type(self).__name__}.ask: the previous batch was not told yet")
        if self._t0 is None:
            self._t0 = _clock()
        self._check_time()
        empty = np.zeros((0, self.dim))
        if self.done:
            return empty
        remaining = None if self.max_evals is None else self.max_evals - self.nfev
        u = np.asarray(self._ask(remaining), dtype=np.float64).reshape(-1, self.dim)
        if remaining is not None and len(u) > remaining:
            raise RuntimeError(f"{type(self).__name__}._ask returned {len(u)} points with {remaining} evaluations left")
        if len(u) == 0:
            if not self.done:
                self._finish(Status.CONVERGED, f"{self.name}: no points left to evaluate")
            return empty
        u = np.clip(u, 0.0, 1.0)
        x = self.box.from_unit(u)
        self._pending = (x, u)
        return x.copy()

    def tell(self, x: np.ndarray, values: np.ndarray | Evaluations, *, grad: np.ndarray | None = None,
             times: np.ndarray | None = None) -> None:
        """Record the values ``(n,)`` of the batch ``x`` ``(n, d)`` returned by the last :meth:`ask`.

        ``values``: ``(n,)`` values, or :class:`Evaluations` (values and a failure reason per point, ``""`` =
        success). A point with a reason is a failed evaluation whose value the search still uses; NaN/±inf
        values are failed evaluations too (recorded, never the best). ``grad`` ``(n, d)`` is the gradient
        w.r.t. the real-unit point, required by gradient methods (``needs_gradient``) and ignored otherwise.
        ``times`` ``(n,)``: when each evaluation completed, seconds on the search's clock (:meth:`elapsed`);
        None = now for all.
        """
        if self._pending is None:
            raise RuntimeError(f"{type(self).__name__}.tell: no batch pending; call ask() first")
        xr, u = self._pending
        x = np.asarray(x, dtype=np.float64)
        if x.shape != xr.shape or not np.array_equal(x, xr):
            raise ValueError(f"tell: x must be the batch returned by the last ask() (shape {xr.shape}), got shape {x.shape}")
        v, reasons = self._values(values, len(xr))
        ts = self._times(times, len(xr))
        if grad is not None:
            grad = np.asarray(grad, dtype=np.float64)
            if grad.shape != xr.shape:
                raise ValueError(f"tell: grad must have shape {xr.shape}, got {grad.shape}")
        elif self.needs_gradient:
            raise ValueError(f"tell: method {self.name!r} needs grad= (gradient of the values w.r.t. x, shape {xr.shape})")
        i = self._first_breach(v)
        if i is not None and i < len(v) - 1:  # a breach before the batch's end: record up to it, untold to the method
            self._cut(i + 1, v, reasons, ts, Status.TARGET_REACHED, "")
            return
        self._pending = None
        failed = self._record(xr, v, reasons, ts)
        extras = self._tell(u, v, failed, grad) or {}
        self._t_last = self.elapsed()
        self.trace.append(self._row(len(v), extras))
        self._check_stops(v, failed)

    def tell_partial(self, x: np.ndarray, values: np.ndarray | Evaluations, *, times: np.ndarray | None = None,
                     message: str | None = None) -> None:
        """Record the evaluated first ``k`` points of the pending batch (``x`` = its first ``k`` rows, ``k`` may be
        0) and stop: status TARGET_REACHED when they hold a breach (``stop_above``; the record then ends at the
        first one), else TIME_OUT (the time budget ran out between chunks).

        The points count like any other (``nfev``, best, trace row with ``extra["partial"]``); the method never
        sees the cut batch, so its state stays that of the last complete batch.
        """
        if self._pending is None:
            raise RuntimeError(f"{type(self).__name__}.tell_partial: no batch pending; call ask() first")
        xr, _ = self._pending
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.dim)
        k = len(x)
        if k > len(xr) or not np.array_equal(x, xr[:k]):
            raise ValueError(f"tell_partial: x must be the first rows of the last ask()'s batch ({len(xr)} points), "
                             f"got shape {x.shape}")
        v, reasons = self._values(values, k)
        ts = self._times(times, k)
        i = self._first_breach(v)
        if i is not None:
            self._cut(i + 1, v, reasons, ts, Status.TARGET_REACHED, "")
            return
        self._cut(k, v, reasons, ts, Status.TIME_OUT, message or f"max_seconds={self.max_seconds:g} reached after "
                  f"{self.nfev + k} evaluations (a batch of {len(xr)} cut after {k})")

    def _first_breach(self, v: np.ndarray) -> int | None:
        """Index of the first breach (a finite value ``> stop_above``) in a batch's values ``v``, or None."""
        if self.stop_above is None:
            return None
        hit = np.flatnonzero(np.isfinite(v) & (v > self.stop_above))
        return int(hit[0]) if len(hit) else None

    def _cut(self, k: int, v: np.ndarray, reasons: tuple[str, ...], ts: np.ndarray, status: Status,
             message: str) -> None:
        """Record the first ``k`` points of the pending batch (of values ``v``, reasons, times ``ts``) without telling
        the method, and stop with ``status`` (TARGET_REACHED: the message names the breach)."""
        xr, _ = self._pending
        self._pending = None
        if k:
            self._record(xr[:k], v[:k], tuple(reasons[:k]), ts[:k])
            self._t_last = float(ts[k - 1])
            self.trace.append(self._row(k, {"extra": {PARTIAL: True}}))
        if status is Status.TARGET_REACHED:
            message = f"value {self._best_value:g} > stop_above={self.stop_above:g}"
        self._finish(status, message)

    def time_up(self, pending: int = 0) -> bool:
        """True when the time budget is spent (and ``min_evals``, counting ``pending`` evaluations of the batch
        in progress, is reached): no further batch or chunk may start."""
        if self.max_seconds is None or self.elapsed() < self.max_seconds:
            return False
        return self.min_evals is None or self.nfev + pending >= self.min_evals

    def stop(self, message: str = "stopped by the caller") -> None:
        """End the search now (status STOPPED) unless it already stopped."""
        if self._pending is not None:
            raise RuntimeError(f"{type(self).__name__}.stop: a batch is pending; tell it first")
        if not self.done:
            self._finish(Status.STOPPED, message)

    def result(self) -> SearchResult:
        """The current :class:`SearchResult` (status RUNNING while the search has not stopped)."""
        xs = np.concatenate(self._xs) if self._xs else np.zeros((0, self.dim))
        fs = np.concatenate(self._fs) if self._fs else np.zeros(0)
        ts = np.concatenate(self._ts) if self._ts else np.zeros(0)
        last = self.trace[-1] if self.trace else None
        return SearchResult(
            x=None if self._best_x is None else self._best_x.copy(),
            fun=self._best_value,
            nfev=self.nfev,
            nit=self.nit,
            status=self.status,
            message=self.message,
            elapsed=self._t_last,
            trace=tuple(self.trace),
            xs=xs,
            fs=fs,
            method=self.name,
            names=self.box.names,
            seed=self.seed,
            n_failed=self.n_failed,
            reasons=tuple(self._reasons),
            x_reason=self._best_reason,
            lipschitz_estimate=None if last is None else last.lipschitz_estimate,
            bound_estimate=None if last is None else last.bound_estimate,
            upper_bound=self.upper_bound(),
            lipschitz=self.lipschitz,
            lipschitz_norm=self.lipschitz_norm,
            times=ts,
        )

    def verdict(self, threshold: float) -> Verdict:
        return verdict_for(self._best_value, self.upper_bound(), float(threshold))

    def upper_bound(self) -> float | None:
        """Sound upper bound over the box (needs ``lipschitz`` and a cover from the method), else None."""
        if self.lipschitz is None:
            return None
        cover = self._cover()
        if cover is None:
            return None
        values, half_widths_unit = cover
        return sound_upper_bound(values, half_widths_unit * self.box.width, self.lipschitz, self.lipschitz_norm or "2")

    def cells(self) -> Cells | None:
        """The cells of the box this search has built so far (:class:`~vbl_robust.search.cells.Cells`: centres,
        half-widths and bounds in real units, values, failed flags, volume fractions), or None for a method that
        keeps no cover (random, Sobol, APGD) or before its first complete batch.

        DIRECT family: the current rectangles (a batch asked but not yet told is not part of them). Grid: one cell
        per node, half a spacing around it clipped to the box; nodes not evaluated yet are cells with
        ``failed=True``. The cells are what :mod:`vbl_robust.search.zones` classifies into breached / undecided / ruled-out
        zones.
        """
        return None

    # -- hooks ----------------------------------------------------------------------------------------------
    def _ask(self, remaining: int | None) -> np.ndarray:
        raise NotImplementedError

    def _tell(self, u: np.ndarray, values: np.ndarray, failed: np.ndarray, grad: np.ndarray | None) -> dict[str, Any] | None:
        """Update the method's state; may return TraceRow fields (``po_count_before`` …, or ``extra``)."""
        raise NotImplementedError

    def _complete(self) -> str | None:
        """A message when the method has nothing left to evaluate (checked after each tell), else None."""
        return None

    def _cover(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(values (m,), unit-cube half-widths (m, d))`` of cells covering the box, or None."""
        return None

    # -- internals --------------------------------------------------------------------------------------
    def _values(self, values: np.ndarray | Evaluations, n: int) -> tuple[np.ndarray, tuple[str, ...]]:
        values, given = split(values)
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (n,):
            v = v.reshape(-1) if v.size == n else v
        if v.shape != (n,):
            raise ValueError(f"tell: values must have shape ({n},), got {np.shape(values)}")
        return v, recorded_reasons(v, given)

    def _times(self, times: np.ndarray | None, n: int) -> np.ndarray:
        if times is None:
            return np.full(n, self.elapsed())
        ts = np.asarray(times, dtype=np.float64).reshape(-1)
        if ts.shape != (n,):
            raise ValueError(f"tell: times must have shape ({n},), got {np.shape(times)}")
        return ts

    def _record(self, xr: np.ndarray, v: np.ndarray, reasons: tuple[str, ...], ts: np.ndarray) -> np.ndarray:
        """Bookkeeping of evaluated points (counts, best, stored points); returns the mask of non-finite values."""
        failed = ~np.isfinite(v)
        self._xs.append(xr)
        self._fs.append(v.copy())
        self._reasons.extend(reasons)
        self._ts.append(ts.copy())
        self.nfev += len(v)
        self.nit += 1
        self.n_failed += sum(1 for r in reasons if r)
        if not failed.all():
            i = int(np.argmax(np.where(failed, -np.inf, v)))
            if self._best_x is None or v[i] > self._best_value:
                self._best_value, self._best_x, self._best_reason = float(v[i]), xr[i].copy(), reasons[i]
        return failed

    def _finish(self, status: Status, message: str) -> None:
        self.status, self.message = status, message
        logger.debug("%s stopped: %s (%s) after %d evaluations", self.name, status.value, message, self.nfev)

    def _check_time(self) -> None:
        if not self.done and self.time_up():
            self._finish(Status.TIME_OUT, f"max_seconds={self.max_seconds:g} reached after {self.nfev} evaluations")

    def _check_stops(self, v: np.ndarray, failed: np.ndarray) -> None:
        if self.done:
            return
        if self.stop_above is not None and np.any(~failed & (v > self.stop_above)):
            self._finish(Status.TARGET_REACHED, f"value {self._best_value:g} > stop_above={self.stop_above:g}")
        elif (why := self._complete()) is not None:
            self._finish(Status.CONVERGED, why)
        elif self.max_evals is not None and self.nfev >= self.max_evals:
            self._finish(Status.BUDGET_EXHAUSTED, f"max_evals={self.max_evals} evaluations used")
        elif self.max_iters is not None and self.nit >= self.max_iters:
            self._finish(Status.BUDGET_EXHAUSTED, f"max_iters={self.max_iters} iterations done")
        else:
            self._check_time()

    def _row(self, batch_size: int, extras: dict[str, Any]) -> TraceRow:
        bx = None if self._best_x is None else tuple(float(a) for a in self._best_x)
        ub = self.upper_bound()
        if ub is not None:
            extras = {**extras, "upper_bound": ub}
        return TraceRow(
            iteration=self.nit,
            nfev=self.nfev,
            elapsed=self._t_last,
            best_value=self._best_value,
            best_x=bx,
            batch_size=batch_size,
            n_failed=self.n_failed,
            **extras,
        )
