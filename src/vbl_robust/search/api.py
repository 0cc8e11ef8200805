"""``maximize(f, box, method=...)``: the ask/tell loop, and the registry of methods by name.

Time budgets: with ``max_seconds`` the loop evaluates each batch in *chunks* and stops between chunks, so a search
overshoots its budget by at most the chunk running when the budget ran out; the result then counts only the
evaluations completed by ``max_seconds`` (:func:`~vbl_robust.search.anytime.at_budget`). Chunk sizes: the first
chunk of a search is one point (it measures the rate, points per second of objective calls); each later one
takes at most :data:`CHUNK_TIME_FRACTION` of the time left before the next deadline at the measured rate (at
least 1 point, at most ``chunk_size``), so chunks shrink towards a deadline and the overshoot is small besides
bounded. The deadlines are ``max_seconds`` and the ``time_marks`` (smaller time budgets to be read off the run):
sized against the same deadlines, the run's prefix at a mark is exactly the run a search stopped there (with the
marks below it) would have made, and one run answers every time budget.
Breaches: with ``stop_above`` (and no time budget) a batch is evaluated in chunks of ``chunk_size`` points in
the order the method asks for them, and the search stops after the chunk holding its first breach; only the
points up to that breach are recorded (:meth:`~vbl_robust.search.base.Optimizer.tell`), so the result does not depend
on the chunk size — the chunk size only bounds the evaluations computed beyond the breach (on a CPU a point costs
about as much in a small chunk as in a large one: small chunks; on a GPU a whole batch costs about as much as one
point: one chunk per batch).
Otherwise a batch is one objective call.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..space import ParameterBox
from .adaptive import AdaptiveGeoRobust, AdaptiveGeoRobustV
from .anytime import at_budget
from .apgd import APGD
from .base import Optimizer
from .direct import Direct, DirectL, GeoRobust
from .evaluations import Evaluations, split
from .result import SearchResult, TraceRow
from .sampling import GridSearch, RandomSearch, SobolSearch

#: Search methods by name (campaigns and the CLI pick them by name).
METHODS: dict[str, type[Optimizer]] = {
    "georobust": GeoRobust,
    "georobust-a": AdaptiveGeoRobust,
    "georobust-av": AdaptiveGeoRobustV,
    "direct": Direct,
    "direct-l": DirectL,
    "random": RandomSearch,
    "sobol": SobolSearch,
    "apgd": APGD,
    "grid": GridSearch,
}

_BUDGET_ARGS = {"max_evals", "max_iters", "max_seconds", "min_evals", "stop_above", "seed"}

#: Most points per objective call while a time budget runs (the pipeline objective's default detector batch).
DEFAULT_CHUNK = 32
#: A chunk is sized to take at most this fraction of the time left before the next deadline (measured rate).
CHUNK_TIME_FRACTION = 0.5


def anytime_methods() -> tuple[str, ...]:
    """Names of the registered methods whose points do not depend on their budget (``Optimizer.anytime``): a run at
    the largest budget answers every smaller one (:func:`~vbl_robust.search.anytime.at_budget`)."""
    return tuple(name for name, cls in METHODS.items() if cls.anytime)


def direct_family() -> tuple[str, ...]:
    """Names of the registered DIRECT-family methods (their trace has |PO_k| and RA(k))."""
    return tuple(name for name, cls in METHODS.items() if issubclass(cls, Direct))


def method_options(method: str) -> list[str]:
    """Names of the keyword options of ``method`` (besides budgets and seed)."""
    cls = _method(method)
    names: list[str] = []
    for klass in cls.__mro__:
        if klass is object:
            continue
        for p in inspect.signature(klass.__init__).parameters.values():
            if p.kind is p.KEYWORD_ONLY and p.name not in _BUDGET_ARGS and p.name not in names:
                names.append(p.name)
    return names


def make_optimizer(method: str, box: ParameterBox, **kwargs: Any) -> Optimizer:
    """Instantiate a registered method; unknown options raise a ValueError naming them."""
    cls = _method(method)
    allowed = set(method_options(method)) | _BUDGET_ARGS
    unknown = sorted(set(kwargs) - allowed)
    if unknown:
        raise ValueError(f"method {method!r} has no option(s) {unknown}; options are {sorted(allowed - _BUDGET_ARGS)}")
    return cls(box, **kwargs)


def maximize(
    f: Callable[[Any], Any],
    box: ParameterBox,
    method: str = "georobust",
    *,
    max_evals: int | None = None,
    max_iters: int | None = None,
    max_seconds: float | None = None,
    min_evals: int | None = None,
    time_marks: Sequence[float] = (),
    chunk_size: int = DEFAULT_CHUNK,
    stop_above: float | None = None,
    seed: int = 0,
    callback: Callable[[TraceRow], bool | None] | None = None,
    **method_options: Any,
) -> SearchResult:
    """Maximise ``f`` over ``box`` with a registered method.

    Args:
        f: batched objective. For every method but ``"apgd"``: ``(n, d)`` numpy array in real units (columns
            ordered as ``box.names``) -> ``(n,)`` values (numpy, list or torch tensor). For ``"apgd"``: a
            torch-differentiable function: it receives a ``torch.float64`` tensor ``(n, d)`` with
            ``requires_grad=True`` and must return a ``(n,)`` tensor connected to it by autograd, each value
            depending on its own row only (the gradient is taken of the sum). The pipeline's objectives
            (:class:`vbl_robust.Objective`) are both kinds: the type of θ picks their path. Either kind of ``f``
            may instead return
            :class:`~vbl_robust.search.evaluations.Evaluations` (the values as above, and a failure reason per point, ``""``
            = success): the search uses the values, the result counts the failures per reason. NaN/inf values
            are failed evaluations, never errors.
        box: the search space.
        method: a key of :data:`METHODS`.
        max_evals, max_iters, max_seconds: budgets; at least one is required. ``max_evals`` is never
            exceeded; ``max_seconds`` is checked between chunks of a batch (see the module docstring) and the
            result counts only the evaluations completed by then.
        min_evals: with ``max_seconds``, keep going until this many evaluations are done too (a run from which
            every smaller time and evaluation budget is read; its result is not cut at ``max_seconds``).
        time_marks: smaller time budgets to be read off this run (chunks are sized against each in turn).
        chunk_size: most points per objective call while a time budget runs or ``stop_above`` may stop the search
            inside a batch (see the module docstring).
        stop_above: stop at the first value ``> stop_above`` (status TARGET_REACHED); the record ends there.
        seed: seed of the method's random choices (same seed → same run).
        callback: called with each iteration's :class:`TraceRow`; returning True stops (status STOPPED).
        **method_options: options of the method's class (e.g. ``alpha=2`` for GeoRobust, ``counts=`` for grid,
            ``lipschitz=`` for a sound bound).

    >>> from vbl_robust.space import ParameterBox
    >>> r = maximize(lambda x: -((x - 0.3) ** 2).sum(axis=1), ParameterBox({"a": (-1, 1)}), "direct", max_evals=60)
    >>> round(float(r.x[0]), 2), r.nfev <= 60
    (0.3, True)
    """
    if max_evals is None and max_iters is None and max_seconds is None:
        raise ValueError("maximize: at least one budget is required (max_evals, max_iters or max_seconds)")
    if not isinstance(chunk_size, int | np.integer) or isinstance(chunk_size, bool) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    marks = _check_marks(time_marks, max_seconds)
    opt = make_optimizer(
        method, box, max_evals=max_evals, max_iters=max_iters, max_seconds=max_seconds, min_evals=min_evals,
        stop_above=stop_above, seed=seed, **method_options,
    )
    if opt.needs_gradient:
        evaluate = _with_gradient(f, method)
    else:
        evaluate = _values_only(f)
    chunks = _Chunks(opt, int(chunk_size), marks) if max_seconds is not None or stop_above is not None else None
    while len(x := opt.ask()):
        if chunks is None or (max_seconds is None and len(x) <= chunk_size):
            b = evaluate(x)
            opt.tell(x, b.told(), grad=b.grad)
        elif not chunks.run(x, evaluate):
            break  # cut by the time budget or at a breach (recorded by tell_partial)
        if callback is not None and callback(opt.trace[-1]) is True and not opt.done:
            opt.stop("stopped by callback")
    result = opt.result()
    if max_seconds is not None and min_evals is None:
        result = at_budget(result, seconds=max_seconds)
    return result


def _check_marks(time_marks: Sequence[float], max_seconds: float | None) -> tuple[float, ...]:
    marks = tuple(time_marks)
    if marks and max_seconds is None:
        raise ValueError(f"time_marks={marks!r} need max_seconds")
    for t in marks:
        if isinstance(t, bool) or not isinstance(t, int | float | np.number) or not (math.isfinite(t) and t > 0):
            raise ValueError(f"time_marks must be finite numbers > 0, got {marks!r}")
    return tuple(float(t) for t in marks)


class _Chunks:
    """Evaluates a batch in chunks while a time budget runs or a breach may stop the search (sizes: see the module
    docstring)."""

    def __init__(self, opt: Optimizer, cap: int, marks: tuple[float, ...]):
        self.opt, self.cap = opt, cap
        self.deadlines = sorted({*marks, float(opt.max_seconds)}) if opt.max_seconds is not None else []
        self.points, self.seconds = 0, 0.0  # evaluated so far, and the seconds their objective calls took

    def size(self, left: int) -> int:
        if not self.deadlines:  # no time budget: fixed chunks
            return min(left, self.cap)
        now = self.opt.elapsed()
        nxt = next((d for d in self.deadlines if d > now), None)
        if nxt is None:  # past every deadline (min_evals keeps it going): full chunks
            return min(left, self.cap)
        if self.points == 0:
            return 1  # a probe of the rate
        rate = self.points / max(self.seconds, 1e-12)
        return max(1, min(left, self.cap, int(CHUNK_TIME_FRACTION * rate * (nxt - now))))

    def run(self, x: np.ndarray, evaluate: Callable[[np.ndarray], _Batch]) -> bool:
        """Evaluate and tell the batch ``x``; False when the time budget or a breach cut it (told with
        ``tell_partial``)."""
        opt, n, done = self.opt, len(x), 0
        parts: list[_Batch] = []
        times: list[np.ndarray] = []
        while done < n:
            if done and (opt.time_up(done) or opt._first_breach(parts[-1].values) is not None):
                break
            k = self.size(n - done)
            t0 = opt.elapsed()
            parts.append(evaluate(x[done : done + k]))
            t1 = opt.elapsed()
            self.points, self.seconds = self.points + k, self.seconds + (t1 - t0)
            times.append(np.full(k, t1))
            done += k
        batch = _Batch.concat(parts)
        if done < n:
            opt.tell_partial(x[:done], batch.told(), times=np.concatenate(times))
            return False
        opt.tell(x, batch.told(), grad=batch.grad, times=np.concatenate(times))
        return True


@dataclass(frozen=True)
class _Batch:
    """One evaluated chunk: values, the failure reason per point (None when ``f`` gave plain values) and the
    gradient (gradient methods); the objective's :class:`Evaluations` are split once on the way in and wrapped once
    on the way to the optimizer (:meth:`told`)."""

    values: np.ndarray
    reasons: tuple[str, ...] | None
    grad: np.ndarray | None = None

    def told(self) -> np.ndarray | Evaluations:
        return self.values if self.reasons is None else Evaluations(self.values, self.reasons)

    @staticmethod
    def concat(parts: Sequence[_Batch]) -> _Batch:
        if len(parts) == 1:
            return parts[0]
        given = [p.reasons for p in parts]
        reasons = None if all(r is None for r in given) else tuple(
            r for p, g in zip(parts, given, strict=True) for r in (g if g is not None else ("",) * len(p.values)))
        grad = None if parts[0].grad is None else np.concatenate([p.grad for p in parts])
        return _Batch(np.concatenate([p.values for p in parts]), reasons, grad)


def _method(method: str) -> type[Optimizer]:
    try:
        return METHODS[method]
    except (KeyError, TypeError):
        raise ValueError(f"unknown search method {method!r}; methods are {sorted(METHODS)}") from None


def _as_values(y: Any, n: int) -> np.ndarray:
    if hasattr(y, "detach"):
        y = y.detach().cpu().numpy()
    v = np.asarray(y, dtype=np.float64)
    if v.shape != (n,):
        raise ValueError(f"f must return shape ({n},) for an input of shape ({n}, d), got {v.shape}")
    return v


def _values_only(f: Callable[[np.ndarray], Any]) -> Callable[[np.ndarray], _Batch]:
    def evaluate(x: np.ndarray) -> _Batch:
        y, reasons = split(f(x))
        return _Batch(_as_values(y, len(x)), reasons)

    return evaluate


def _with_gradient(f: Callable[[Any], Any], method: str) -> Callable[[np.ndarray], _Batch]:
    import torch

    hint = (
        f"method {method!r} needs a torch-differentiable f: it is called with a torch.float64 tensor (n, d) "
        "with requires_grad=True and must return a (n,) tensor computed from it with torch operations"
    )

    def evaluate(x: np.ndarray) -> _Batch:
        xt = torch.tensor(x, dtype=torch.float64, requires_grad=True)
        with torch.enable_grad():
            try:
                y, reasons = split(f(xt))
            except (TypeError, RuntimeError) as e:
                raise ValueError(f"{hint}; calling f failed: {e}") from e
            if not isinstance(y, torch.Tensor):
                raise ValueError(f"{hint}; f returned {type(y).__name__}")
            if y.shape != (len(x),):
                raise ValueError(f"{hint}; f returned shape {tuple(y.shape)} for input ({len(x)}, {x.shape[1]})")
            if not y.requires_grad:
                raise ValueError(f"{hint}; the returned tensor has no gradient (requires_grad=False)")
            (g,) = torch.autograd.grad(y.sum(), xt, allow_unused=True)
        if g is None:
            raise ValueError(f"{hint}; the returned tensor does not depend on the input")
        values = y.detach().cpu().numpy().astype(np.float64)
        return _Batch(values, reasons, g.detach().cpu().numpy().astype(np.float64))

    return evaluate
