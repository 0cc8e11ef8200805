"""The classical test functions of the DIRECT literature (Jones et al. 1993; Gablonsky 2001), batched, and
anisotropic ones (a rough 1-D function embedded in more dimensions).

Each :class:`TestFunction` is to be *minimised* (``f(x)`` for ``x`` of shape ``(n, d)`` returns ``(n,)``),
with its box and known global minimum ``f_star``; maximise ``-f`` with our searches. An :class:`Anisotropic`
function is to be *maximised* over the unit cube (its maximum ``f_max`` is computed once).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..space import ParameterBox


@dataclass(frozen=True)
class TestFunction:
    name: str
    f: Callable[[np.ndarray], np.ndarray]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    f_star: float

    __test__ = False  # not a pytest class

    @property
    def dim(self) -> int:
        return len(self.lower)

    def box(self) -> ParameterBox:
        return ParameterBox({f"x{i}": (a, b) for i, (a, b) in enumerate(zip(self.lower, self.upper, strict=True))})

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.f(np.atleast_2d(np.asarray(x, dtype=np.float64)))

    def reached(self, value: float, tol: float = 1e-4) -> bool:
        """``(value - f*) / |f*| < tol`` (0.01 % for tol = 1e-4)."""
        return (value - self.f_star) / abs(self.f_star) < tol


_SHEKEL_A = np.array(
    [[4, 4, 4, 4], [1, 1, 1, 1], [8, 8, 8, 8], [6, 6, 6, 6], [3, 7, 3, 7],
     [2, 9, 2, 9], [5, 5, 3, 3], [8, 1, 8, 1], [6, 2, 6, 2], [7, 3.6, 7, 3.6]], dtype=np.float64,
)
_SHEKEL_C = np.array([0.1, 0.2, 0.2, 0.4, 0.4, 0.6, 0.3, 0.7, 0.5, 0.5])


def _shekel(m: int) -> Callable[[np.ndarray], np.ndarray]:
    def f(x: np.ndarray) -> np.ndarray:
        diff = x[:, None, :] - _SHEKEL_A[None, :m, :]
        return -np.sum(1.0 / (np.sum(diff * diff, axis=2) + _SHEKEL_C[None, :m]), axis=1)

    return f


_H3_A = np.array([[3.0, 10, 30], [0.1, 10, 35], [3.0, 10, 30], [0.1, 10, 35]])
_H3_P = np.array([[0.3689, 0.1170, 0.2673], [0.4699, 0.4387, 0.7470], [0.1091, 0.8732, 0.5547], [0.0381, 0.5743, 0.8828]])
_H6_A = np.array([[10, 3, 17, 3.5, 1.7, 8], [0.05, 10, 17, 0.1, 8, 14], [3, 3.5, 1.7, 10, 17, 8], [17, 8, 0.05, 10, 0.1, 14]])
_H6_P = 1e-4 * np.array(
    [[1312, 1696, 5569, 124, 8283, 5886], [2329, 4135, 8307, 3736, 1004, 9991],
     [2348, 1451, 3522, 2883, 3047, 6650], [4047, 8828, 8732, 5743, 1091, 381]]
)
_H_C = np.array([1.0, 1.2, 3.0, 3.2])


def _hartman(a: np.ndarray, p: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    def f(x: np.ndarray) -> np.ndarray:
        diff = x[:, None, :] - p[None]
        return -np.sum(_H_C[None] * np.exp(-np.sum(a[None] * diff * diff, axis=2)), axis=1)

    return f


def _branin(x: np.ndarray) -> np.ndarray:
    x1, x2 = x[:, 0], x[:, 1]
    return (x2 - 5.1 / (4 * np.pi**2) * x1**2 + 5 / np.pi * x1 - 6) ** 2 + 10 * (1 - 1 / (8 * np.pi)) * np.cos(x1) + 10


def _goldstein_price(x: np.ndarray) -> np.ndarray:
    x1, x2 = x[:, 0], x[:, 1]
    a = 1 + (x1 + x2 + 1) ** 2 * (19 - 14 * x1 + 3 * x1**2 - 14 * x2 + 6 * x1 * x2 + 3 * x2**2)
    b = 30 + (2 * x1 - 3 * x2) ** 2 * (18 - 32 * x1 + 12 * x1**2 + 48 * x2 - 36 * x1 * x2 + 27 * x2**2)
    return a * b


def _six_hump_camel(x: np.ndarray) -> np.ndarray:
    x1, x2 = x[:, 0], x[:, 1]
    return (4 - 2.1 * x1**2 + x1**4 / 3) * x1**2 + x1 * x2 + (-4 + 4 * x2**2) * x2**2


def _shubert(x: np.ndarray) -> np.ndarray:
    i = np.arange(1, 6, dtype=np.float64)
    s1 = np.sum(i * np.cos((i + 1) * x[:, :1] + i), axis=1)
    s2 = np.sum(i * np.cos((i + 1) * x[:, 1:2] + i), axis=1)
    return s1 * s2


#: The nine functions, in the order of the DIRECT tables.
CLASSIC: dict[str, TestFunction] = {
    t.name: t
    for t in (
        TestFunction("shekel5", _shekel(5), (0.0,) * 4, (10.0,) * 4, -10.1531996790582),
        TestFunction("shekel7", _shekel(7), (0.0,) * 4, (10.0,) * 4, -10.4029405668187),
        TestFunction("shekel10", _shekel(10), (0.0,) * 4, (10.0,) * 4, -10.536409816692),
        TestFunction("hartman3", _hartman(_H3_A, _H3_P), (0.0,) * 3, (1.0,) * 3, -3.86278214782076),
        TestFunction("hartman6", _hartman(_H6_A, _H6_P), (0.0,) * 6, (1.0,) * 6, -3.32236801141551),
        TestFunction("branin", _branin, (-5.0, 0.0), (10.0, 15.0), 0.397887357729739),
        TestFunction("goldstein_price", _goldstein_price, (-2.0, -2.0), (2.0, 2.0), 3.0),
        TestFunction("six_hump_camel", _six_hump_camel, (-3.0, -2.0), (3.0, 2.0), -1.03162845348988),
        TestFunction("shubert", _shubert, (-10.0, -10.0), (10.0, 10.0), -186.730908831024),
    )
}


# -- evaluation counts to the classical target (used by the tests and benchmarks/bench_search.py) ---------
@dataclass(frozen=True)
class Count:
    """Evaluations until the best value is within ``tol`` (relative) of ``f*``.

    ``nfev`` = evaluations when the run stopped (ours: at the end of the iteration that reached the target),
    ``first`` = index (1-based) of the first evaluation that reached it, ``nit`` = iterations (batches) or None.
    All None when the target was not reached within the budget.
    """

    nfev: int | None
    first: int | None
    nit: int | None


def count_ours(t: TestFunction, method: str, *, tol: float = 1e-4, max_evals: int = 20000, **options) -> Count:
    from .api import maximize

    target = t.f_star + tol * abs(t.f_star)
    r = maximize(lambda x: -t(x), t.box(), method, max_evals=max_evals, stop_above=-target, **options)
    if not t.reached(-r.fun, tol):
        return Count(None, None, None)
    first = int(np.flatnonzero(r.fs > -target)[0]) + 1
    return Count(r.nfev, first, r.nit)


def _counted(t: TestFunction) -> tuple[Callable[[np.ndarray], float], list[float]]:
    seen: list[float] = []

    def f(x, *_):
        v = float(t(np.asarray(x))[0])
        seen.append(v)
        return v

    return f, seen


def _count(t: TestFunction, seen: list[float], tol: float, nit: int | None = None) -> Count:
    hits = [i for i, v in enumerate(seen) if t.reached(v, tol)]
    if not hits:
        return Count(None, None, None)
    return Count(len(seen), hits[0] + 1, nit)


def count_scipy(t: TestFunction, *, locally_biased: bool, tol: float = 1e-4, max_evals: int = 20000) -> Count:
    """``scipy.optimize.direct`` (Gablonsky's code) stopped by its ``f_min``/``f_min_rtol`` test."""
    from scipy.optimize import direct

    f, seen = _counted(t)
    r = direct(f, list(zip(t.lower, t.upper, strict=True)), maxfun=max_evals, maxiter=10**6,
               locally_biased=locally_biased, f_min=t.f_star, f_min_rtol=tol)
    return _count(t, seen, tol, int(r.nit))


def count_nlopt(t: TestFunction, algorithm: str, *, tol: float = 1e-4, max_evals: int = 20000) -> Count:
    """NLopt's DIRECT variant ``algorithm`` (e.g. ``"GN_ORIG_DIRECT"``), stopped by ``stopval``."""
    import nlopt

    f, seen = _counted(t)
    opt = nlopt.opt(getattr(nlopt, algorithm), t.dim)
    opt.set_min_objective(f)
    opt.set_lower_bounds(list(t.lower))
    opt.set_upper_bounds(list(t.upper))
    opt.set_maxeval(max_evals)
    opt.set_stopval(t.f_star + tol * abs(t.f_star) * (1 - 1e-9))
    try:
        opt.optimize([0.5 * (a + b) for a, b in zip(t.lower, t.upper, strict=True)])
    except (RuntimeError, ValueError):  # NLopt reports some stops as exceptions; the counts stay valid
        pass
    return _count(t, seen, tol)


# -- anisotropic test functions: a rough 1-D function embedded in d dimensions -------------------------------
#: Widths of the rough function's peaks (unit interval): 0.1–0.3° of a 30° roll box, the pipeline's scale.
ROUGH_WIDTHS = (0.003, 0.01)
#: Width of its tallest peak.
ROUGH_TOP_WIDTH = 0.004


@lru_cache(maxsize=64)
def _rough(seed: int) -> tuple[Callable[[np.ndarray], np.ndarray], float]:
    g = _rough_1d(seed)
    return g, _max_1d(g)


def _rough_1d(seed: int, n_peaks: int = 12) -> Callable[[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0.0, 2 * np.pi, 2)
    centre = rng.uniform(0.02, 0.98, n_peaks + 1)
    width = np.r_[rng.uniform(*ROUGH_WIDTHS, n_peaks), ROUGH_TOP_WIDTH]
    height = np.r_[rng.uniform(0.4, 1.4, n_peaks), 2.0]

    def g(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=np.float64)
        smooth = 1.5 + 0.3 * np.sin(6 * np.pi * a + phase[0]) + 0.2 * np.sin(22 * np.pi * a + phase[1])
        return smooth + np.sum(height * np.exp(-(((a[..., None] - centre) / width) ** 2)), axis=-1)

    return g


def _max_1d(g: Callable[[np.ndarray], np.ndarray], n: int = 400_001) -> float:
    """Maximum of ``g`` on [0, 1]: a dense grid (spacing 2.5e-6, far below the peak widths), then golden-section
    refinement around the best node."""
    a = np.linspace(0.0, 1.0, n)
    i = int(np.argmax(g(a)))
    lo, hi = a[max(i - 1, 0)], a[min(i + 1, n - 1)]
    r = (math.sqrt(5) - 1) / 2
    for _ in range(60):
        x1, x2 = hi - r * (hi - lo), lo + r * (hi - lo)
        if g(np.array([x1]))[0] >= g(np.array([x2]))[0]:
            hi = x2
        else:
            lo = x1
    return float(max(g(np.array([0.5 * (lo + hi)]))[0], g(a[i : i + 1])[0]))


@dataclass(frozen=True)
class Anisotropic:
    """A rough 1-D function ``g`` of the *last* coordinate of the unit cube ``[0, 1]^dim``, to be *maximised*.

    ``g`` (instance ``seed``): a smooth background ``1.5 + 0.3 sin(6πa + φ1) + 0.2 sin(22πa + φ2)`` plus 12 Gaussian
    peaks of heights 0.4–1.4 and widths 0.003–0.01 and one of height 2 and width 0.004, at uniform positions —
    the pipeline's error varies with roll at 0.1–0.3° in a 30° box. The other ``dim - 1`` coordinates are
    irrelevant (``weak = 0``) or add ``weak · sin(3 x_j)`` each (barely relevant, as contrast is). The last
    coordinate is the relevant one so that DIRECT's tie-breaks (lower dimension first) do not favour it.
    ``f_max`` is the maximum over the cube (grid + golden section on ``g``; ``weak · (dim - 1)`` more when weak).
    """

    seed: int
    dim: int
    weak: float = 0.0
    g: Callable[[np.ndarray], np.ndarray] = field(init=False, repr=False, compare=False)
    f_max: float = field(init=False, compare=False)

    __test__ = False

    def __post_init__(self) -> None:
        g, g_max = _rough(self.seed)
        object.__setattr__(self, "g", g)
        object.__setattr__(self, "f_max", g_max + self.weak * (self.dim - 1))

    @property
    def name(self) -> str:
        return f"rough{self.seed}-{self.dim}d" + (f"-weak{self.weak:g}" if self.weak else "")

    def box(self) -> ParameterBox:
        return ParameterBox({f"x{i}": (0.0, 1.0) for i in range(self.dim)})

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        v = self.g(x[:, -1])
        if self.weak and self.dim > 1:
            v = v + self.weak * np.sum(np.sin(3.0 * x[:, :-1]), axis=1)
        return v

    def target(self, tol: float = 0.01) -> float:
        """The value to exceed: within ``tol`` (relative) of the maximum."""
        return self.f_max - tol * abs(self.f_max)


def evals_to_target(t: Anisotropic, method: str, *, tol: float = 0.01, max_evals: int = 4000, seed: int = 0,
                    **options) -> int | None:
    """Index (1-based) of the first evaluation above ``t.target(tol)``, or None if not reached in ``max_evals``."""
    from .api import maximize

    target = t.target(tol)
    r = maximize(t, t.box(), method, max_evals=max_evals, stop_above=target, seed=seed, **options)
    hits = np.flatnonzero(r.fs > target)
    return int(hits[0]) + 1 if len(hits) else None
