"""``maximize(f, box, method=...)``: the ask/tell loop, and the registry of methods by name."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np

from ..space import ParameterBox
from .apgd import APGD
from .base import Optimizer
from .direct import Direct, DirectL, GeoRobust
from .evaluations import Evaluations, split
from .result import SearchResult, TraceRow
from .sampling import GridSearch, RandomSearch, SobolSearch

#: Search methods by name (campaigns and the CLI pick them by name).
METHODS: dict[str, type[Optimizer]] = {
    "georobust": GeoRobust,
    "direct": Direct,
    "direct-l": DirectL,
    "random": RandomSearch,
    "sobol": SobolSearch,
    "apgd": APGD,
    "grid": GridSearch,
}

_BUDGET_ARGS = {"max_evals", "max_iters", "max_seconds", "stop_above", "seed"}


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
            depending on its own row only (the gradient is taken of the sum). An object with a callable
            ``torch`` attribute (such as :class:`vbl_robust.Objective`) is called through it for ``"apgd"``
            and directly for the other methods. Either kind of ``f`` may instead return
            :class:`~vbl_robust.search.Evaluations` (the values as above, and a failure reason per point, ``""``
            = success): the search uses the values, the result counts the failures per reason. NaN/inf values
            are failed evaluations, never errors.
        box: the search space.
        method: a key of :data:`METHODS`.
        max_evals, max_iters, max_seconds: budgets; at least one is required. ``max_evals`` is never
            exceeded; ``max_seconds`` is checked between batches.
        stop_above: stop after the first batch containing a value ``> stop_above`` (status TARGET_REACHED).
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
    opt = make_optimizer(
        method, box, max_evals=max_evals, max_iters=max_iters, max_seconds=max_seconds,
        stop_above=stop_above, seed=seed, **method_options,
    )
    if opt.needs_gradient:
        evaluate = _with_gradient(getattr(f, "torch", None) if callable(getattr(f, "torch", None)) else f, method)
    else:
        evaluate = _values_only(f)
    while len(x := opt.ask()):
        values, grad = evaluate(x)
        opt.tell(x, values, grad=grad)
        if callback is not None and callback(opt.trace[-1]) is True and not opt.done:
            opt.stop("stopped by callback")
    return opt.result()


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


def _with_reasons(values: np.ndarray, reasons: tuple[str, ...] | None) -> np.ndarray | Evaluations:
    return values if reasons is None else Evaluations(values, reasons)


def _values_only(f: Callable[[np.ndarray], Any]) -> Callable[[np.ndarray], tuple[np.ndarray | Evaluations, None]]:
    def evaluate(x: np.ndarray) -> tuple[np.ndarray | Evaluations, None]:
        y, reasons = split(f(x))
        return _with_reasons(_as_values(y, len(x)), reasons), None

    return evaluate


def _with_gradient(f: Callable[[Any], Any], method: str) -> Callable[[np.ndarray], tuple[Any, np.ndarray]]:
    import torch

    hint = (
        f"method {method!r} needs a torch-differentiable f: it is called with a torch.float64 tensor (n, d) "
        "with requires_grad=True and must return a (n,) tensor computed from it with torch operations"
    )

    def evaluate(x: np.ndarray) -> tuple[np.ndarray | Evaluations, np.ndarray]:
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
        return _with_reasons(values, reasons), g.detach().cpu().numpy().astype(np.float64)

    return evaluate
