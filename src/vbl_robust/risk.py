"""Failure probability under a distribution of θ (``vbl-robust risk``): per image, p_fail = P(L(θ) > ε_safe) when
θ follows a declared distribution over the box, with a valid 95 % interval and a verdict on "p_fail ≤ τ".

Turbulence is not a worst case: where the worst-case search answers "is there a breach anywhere in Θ?", this asks
"how often does the pipeline fail when θ varies as it does in flight?". Two estimators, each a job method:

- ``mc`` — plain Monte Carlo with a group-sequential test (:class:`vbl_robust.stats.SequentialTest`): θ drawn
  from the distribution in batches, looked at after 32, 64, 128, … evaluations; it stops as soon as the exact
  interval (level 1 − δ/K over the K looks, so valid under the early stop) decides *holds* (top ≤ τ) or
  *violated* (bottom > τ), else it is *undecided* at ``max_evals``.
- ``guided`` — stratified sampling over the cells of a worst-case search (the search-guided estimator): a short
  GeoRobust-AV run (``guide_evals``, no early stop) tiles the box into DIRECT cells; the cells whose value is above
  ``guide_fraction`` · ε_safe form stratum 1 (where failures are likely), the rest of the box stratum 0. The
  strata's masses under the distribution are exact (products of marginal CDF differences over disjoint cells);
  the remaining evaluations are split between them — by default the split that minimises the interval's expected
  width given the strata's masses and the guide's failure rate in the hot cells (:func:`_allocate`), or ``share``
  to stratum 1 — and drawn from the distribution restricted to each; the interval is the masses' weighting of each
  stratum's one-sided exact bounds, δ shared among them as fixed in advance by :data:`SPLIT`
  (:func:`vbl_robust.stats.stratified_interval`). The guide's own evaluations count in the budget, and its points
  only shape the strata and the split, never the interval: the draws after it are fresh, so the interval is valid
  with probability ≥ 1 − δ over them. Statistical, not a sound certificate: nothing is assumed about L between the
  draws.

  What no estimator can do (measured in BENCHMARKS.md): without an assumption on L, a valid upper bound must allow
  for a failure set hidden where no draw fell, so n draws in a part of mass m that show no failure leave at least
  m·(1 − δ^(1/n)) on top of the estimate. Even with the failure set known for free, reaching plain Monte Carlo's
  half-width at 1024 draws takes 106–263 draws on the benchmark's cases with p_fail ≤ 5 % (3.9–9.7× fewer): the
  search's guidance can only approach that ceiling.

Failed evaluations (no detection, low confidence, …) count as failures (L = the penalty > ε_safe), as everywhere.

The distribution (:class:`ThetaDistribution`) is a product of independent marginals, each uniform over its range
(the default) or a normal truncated to the range (``--dist roll_deg=normal:0,5``).

The estimators here are pure functions of a batched objective; a risk job and its row are
:func:`vbl_robust.campaigns.work.risk_row`, the pooled rate over a run's rows
:func:`vbl_robust.analysis.risk.pooled_risk`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from .space import ParameterBox
from .stats import SequentialTest, Stratum, binomial_bounds, risk_verdict, stratified_interval

__all__ = ["LAWS", "RISK_METHODS", "Law", "Marginal", "RiskResult", "ThetaDistribution", "estimate_risk", "failed",
           "parse_dist"]

#: The estimators (the job methods of a risk campaign).
RISK_METHODS = ("mc", "guided")
#: Defaults: the limit τ on p_fail, δ (1 − confidence), the guide's evaluations, the value fraction of ε_safe above
#: which a guide cell joins stratum 1, and stratum 1's share of the draws.
TAU, DELTA, GUIDE_EVALS, GUIDE_FRACTION, SHARE = 0.01, 0.05, 64, 0.5, None
#: How the guided interval's error δ is shared, fixed before any draw: (lower, upper) shares of stratum 1 (the hot
#: cells: failures likely, both bounds matter) and of stratum 0 (the rest: failures rare, so its lower bound is ≈ 0
#: whatever its share and its upper bound takes most of δ). A run with one stratum uses stratum 0's.
SPLIT = ((0.25, 0.25), (0.05, 0.45))
#: Evaluations per detector call.
BATCH = 32
#: Most evaluations one risk job may spend (a stated bound on ``--max-evals``).
MAX_EVALS = 1_000_000


class Law(StrEnum):
    """The shape of one parameter's distribution (the value is the ``kind`` a risk payload records)."""

    UNIFORM = "uniform"
    NORMAL = "normal"


#: The values of :class:`Law` (what ``--dist NAME=…`` accepts).
LAWS = tuple(law.value for law in Law)


@dataclass(frozen=True)
class Marginal:
    """One parameter's distribution over ``[lo, hi]``: ``uniform``, or ``normal`` (mean ``mu``, sd ``sigma``)
    truncated to the range."""

    kind: Law
    lo: float
    hi: float
    mu: float = 0.0
    sigma: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in LAWS:
            raise ValueError(f"distribution kind must be uniform or normal, got {self.kind!r}")
        object.__setattr__(self, "kind", Law(self.kind))
        if not (math.isfinite(self.lo) and math.isfinite(self.hi) and self.lo < self.hi):
            raise ValueError(f"distribution range must be finite with lo < hi, got [{self.lo}, {self.hi}]")
        if self.kind == Law.NORMAL and not (math.isfinite(self.mu) and math.isfinite(self.sigma) and self.sigma > 0):
            raise ValueError(f"normal: need a finite mean and sigma > 0, got {self.mu}, {self.sigma}")
        if self.kind == Law.NORMAL:
            from scipy.stats import norm

            z = norm(self.mu, self.sigma)
            if not max(z.cdf(self.hi) - z.cdf(self.lo), z.sf(self.lo) - z.sf(self.hi)) > 1e-12:
                raise ValueError(f"normal({self.mu:g}, {self.sigma:g}) has (numerically) no mass in "
                                 f"[{self.lo:g}, {self.hi:g}]")

    def _frozen(self) -> Any:
        from scipy.stats import truncnorm, uniform

        if self.kind == Law.UNIFORM:
            return uniform(self.lo, self.hi - self.lo)
        a, b = (self.lo - self.mu) / self.sigma, (self.hi - self.mu) / self.sigma
        return truncnorm(a, b, loc=self.mu, scale=self.sigma)

    def cdf(self, x: np.ndarray) -> np.ndarray:
        return np.clip(self._frozen().cdf(np.asarray(x, dtype=np.float64)), 0.0, 1.0)

    def ppf(self, q: np.ndarray) -> np.ndarray:
        return np.clip(self._frozen().ppf(np.asarray(q, dtype=np.float64)), self.lo, self.hi)

    def text(self) -> str:
        return "uniform" if self.kind == Law.UNIFORM else f"normal({self.mu:g}, {self.sigma:g}) truncated"


@dataclass(frozen=True)
class ThetaDistribution:
    """A product distribution over a :class:`~vbl_robust.space.ParameterBox` (one :class:`Marginal` per
    parameter, in the box's order)."""

    box: ParameterBox
    marginals: tuple[Marginal, ...]

    @classmethod
    def over(cls, box: ParameterBox, specs: Mapping[str, tuple[str, float, float]] | None = None) -> ThetaDistribution:
        """Uniform over ``box`` except the parameters of ``specs`` (name → ``("normal", mu, sigma)``)."""
        specs = dict(specs or {})
        unknown = sorted(set(specs) - set(box.names))
        if unknown:
            raise ValueError(f"--dist {unknown[0]}: not a parameter of the box ({', '.join(box.names)})")
        margs = []
        for name, lo, hi in zip(box.names, box.lower, box.upper, strict=True):
            kind, mu, sigma = specs.get(name, (Law.UNIFORM, 0.0, 1.0))
            margs.append(Marginal(kind, float(lo), float(hi), float(mu), float(sigma)))
        return cls(box, tuple(margs))

    def sample(self, n: int, rng: np.random.Generator, lower: np.ndarray | None = None,
               upper: np.ndarray | None = None) -> np.ndarray:
        """``(n, d)`` draws, restricted to the rectangle ``[lower, upper]`` when given (inverse CDF between the
        rectangle's CDF values: an exact draw from the restricted distribution)."""
        lower = self.box.lower if lower is None else np.asarray(lower, dtype=np.float64)
        upper = self.box.upper if upper is None else np.asarray(upper, dtype=np.float64)
        u = rng.random((n, len(self.marginals)))
        cols = []
        for j, m in enumerate(self.marginals):
            a, b = m.cdf(lower[j]), m.cdf(upper[j])
            cols.append(np.clip(m.ppf(a + u[:, j] * (b - a)), lower[j], upper[j]))
        return np.stack(cols, axis=1) if cols else np.zeros((n, 0))

    def mass(self, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Probability of each rectangle ``(m, d)`` (products of the marginals' CDF differences)."""
        lower, upper = np.atleast_2d(lower), np.atleast_2d(upper)
        out = np.ones(len(lower))
        for j, m in enumerate(self.marginals):
            out *= m.cdf(upper[:, j]) - m.cdf(lower[:, j])
        return out

    def to_dict(self) -> dict[str, Any]:
        return {n: {"kind": m.kind.value, "mu": m.mu, "sigma": m.sigma} for n, m in zip(self.box.names, self.marginals,
                                                                                 strict=True)}

    def text(self) -> str:
        return ", ".join(f"{n} {m.text()}" for n, m in zip(self.box.names, self.marginals, strict=True))


def parse_dist(items: Sequence[str] | None, names: Sequence[str] | None = None,
               ) -> dict[str, tuple[str, float, float]]:
    """``["roll_deg=normal:0,5", "contrast=uniform"]`` → ``{"roll_deg": ("normal", 0.0, 5.0)}`` (uniform entries
    are the default and dropped); ``ValueError`` naming the item for anything else: a parameter given twice (two
    distributions for one parameter contradict each other, even the same one twice), or — when ``names`` (the box's
    parameters) is given — one not in the box."""
    out: dict[str, tuple[str, float, float]] = {}
    seen: dict[str, str] = {}
    for item in items or ():
        name, _, rest = item.partition("=")
        kind, _, args = rest.partition(":")
        name, kind = name.strip(), kind.strip().lower()
        if not name or kind not in LAWS:
            raise ValueError(f"--dist {item}: expected NAME=uniform or NAME=normal:MEAN,SD")
        if name in seen:
            raise ValueError(f"--dist {item}: {name} is given twice (also --dist {seen[name]}); give one "
                             "distribution per parameter")
        seen[name] = item
        if names is not None and name not in names:
            raise ValueError(f"--dist {item}: {name} is not a parameter of the box ({', '.join(names)})")
        if kind == Law.UNIFORM:
            if args.strip():
                raise ValueError(f"--dist {item}: uniform takes no arguments (its range is the box's)")
            continue
        try:
            mu, sigma = (float(v) for v in args.split(","))
        except ValueError:
            raise ValueError(f"--dist {item}: expected NAME=normal:MEAN,SD") from None
        if not (math.isfinite(mu) and math.isfinite(sigma) and sigma > 0):
            raise ValueError(f"--dist {item}: the mean must be finite and SD > 0")
        out[name] = (Law.NORMAL.value, mu, sigma)
    return out


@dataclass(frozen=True)
class RiskResult:
    """One image's failure probability: ``p_fail`` (the estimate), its interval ``ci`` (fractions), the verdict
    against ``tau``, ``evaluations`` spent, and every evaluated θ with its L and failure reason."""

    method: str
    p_fail: float
    ci: Any
    verdict: str
    evaluations: int
    xs: np.ndarray
    fs: np.ndarray
    reasons: tuple[str, ...]
    eps_safe_m: float
    strata: tuple[Stratum, ...] = ()
    split: tuple[tuple[float, float], ...] = ()  # the shares of δ of each stratum's (lower, upper) bound


def _evaluate(f: Callable[[np.ndarray], Any], x: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]]:
    from .search.evaluations import split

    values, reasons = split(f(x))
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    return v, tuple(reasons) if reasons else ("",) * len(v)


def failed(values: np.ndarray, eps: float) -> np.ndarray:
    """Which of ``values`` (metres) count as failures: above ``eps`` or not finite (a failed evaluation)."""
    return ~np.isfinite(values) | (values > eps)


def _mc(f: Callable, dist: ThetaDistribution, eps: float, tau: float, delta: float, max_evals: int,
        rng: np.random.Generator) -> RiskResult:
    test = SequentialTest.doubling(tau, delta, max_evals)
    xs, fs, reasons = [], [], []
    n = k = 0
    verdict = None
    for look in test.looks:
        while n < look:
            x = dist.sample(min(BATCH, look - n), rng)
            v, r = _evaluate(f, x)
            xs.append(x), fs.append(v), reasons.extend(r)
            n += len(v)
            k += int(failed(v, eps).sum())
        verdict = test.decide(k, n)
        if verdict is not None:
            break
    ci = test.interval(k, n)
    return RiskResult("mc", k / n, ci, verdict.value, n, np.concatenate(xs), np.concatenate(fs), tuple(reasons), eps)


def _guided(f: Callable, dist: ThetaDistribution, eps: float, tau: float, delta: float, max_evals: int,
            rng: np.random.Generator, seed: int, guide_evals: int, guide_fraction: float,
            share: float | None) -> RiskResult:
    from .search.api import make_optimizer

    guide = make_optimizer("georobust-av", dist.box, max_evals=min(guide_evals, max_evals - 2), seed=seed)
    xs, fs, reasons = [], [], []
    while len(x := guide.ask()):
        v, r = _evaluate(f, x)
        guide.tell(x, v)
        xs.append(x), fs.append(v), reasons.extend(r)
    spent = sum(len(v) for v in fs)
    cells = guide.cells()
    hot = np.zeros(0, dtype=bool) if cells is None else (~np.isfinite(cells.values)
                                                        | (cells.values > guide_fraction * eps))
    left = max_evals - spent
    if cells is None or not hot.any():  # nothing to guide by: one stratum, the whole box (plain Monte Carlo)
        lo = hi = np.zeros((0, len(dist.marginals)))
        m1, n1, n0 = 0.0, 0, left
    else:
        lo, hi = cells.lower[hot], cells.upper[hot]
        masses = dist.mass(lo, hi)
        m1 = float(min(max(masses.sum(), 0.0), 1.0))
        m1 = 1.0 if m1 > 1.0 - 1e-9 else (0.0 if m1 < 1e-12 else m1)
        if m1 <= 0.0:  # hot cells with no probability: nothing to draw there
            lo = hi = np.zeros((0, len(dist.marginals)))
        if m1 <= 0.0:
            n1 = 0
        elif m1 >= 1.0:
            n1 = left
        elif share is None:
            n1 = _allocate(m1, _hot_rate(np.concatenate(xs), np.concatenate(fs), lo, hi, eps), left, delta)
        else:
            n1 = min(left - 1, max(1, int(round(share * left))))
        n0 = left - n1
    # stratum 0 first: draws from the distribution, rejected while inside a hot cell (cells are disjoint); what it
    # cannot fill (a stratum of tiny mass) goes to stratum 1
    x0 = np.zeros((0, len(dist.marginals)))
    tries = 0
    while len(x0) < n0 and tries < 200:
        cand = dist.sample(max(2 * (n0 - len(x0)), 8), rng)
        x0 = np.concatenate([x0, cand[~_in_cells(cand, lo, hi)]])[:n0]
        tries += 1
    n1 = left - len(x0) if m1 > 0.0 else 0
    # stratum 1: a cell with probability ∝ its mass, then a draw from the distribution restricted to it
    x1 = np.zeros((0, len(dist.marginals)))
    if n1:
        pick = rng.choice(len(lo), size=n1, p=masses / masses.sum())
        x1 = np.concatenate([dist.sample(int((pick == c).sum()), rng, lo[c], hi[c]) for c in range(len(lo))])
    strata, split = [], []
    for x, mass, shares in ((x1, m1, SPLIT[0]), (x0, 1.0 - m1, SPLIT[1])):
        if mass <= 0.0 and not len(x):
            continue
        split.append(shares)
        k = 0
        for i in range(0, len(x), BATCH):
            v, r = _evaluate(f, x[i:i + BATCH])
            xs.append(x[i:i + BATCH]), fs.append(v), reasons.extend(r)
            k += int(failed(v, eps).sum())
        strata.append(Stratum(mass, k, len(x)))
    total = sum(map(sum, split))  # one stratum left: its shares scaled to the whole δ
    split = [(a / total, b / total) for a, b in split]
    est, ci = stratified_interval(strata, 1.0 - delta, split)
    return RiskResult("guided", est, ci, risk_verdict(ci, tau).value, sum(len(v) for v in fs), np.concatenate(xs),
                      np.concatenate(fs), tuple(reasons), eps, tuple(strata), tuple(split))


def _in_cells(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which rows of ``x`` lie in one of the cells ``[lo[c], hi[c]]``."""
    return np.any(np.all((x[:, None, :] >= lo[None]) & (x[:, None, :] <= hi[None]), axis=2), axis=1)


def _hot_rate(x: np.ndarray, f: np.ndarray, lo: np.ndarray, hi: np.ndarray, eps: float) -> float:
    """The guide's failure rate inside the hot cells (Laplace-smoothed, kept in [0.05, 0.95]): an estimate used only
    to split the draws, never in the interval (the guide's points are not a sample of the distribution)."""
    inside = _in_cells(x, lo, hi)
    k, n = int(failed(f[inside], eps).sum()), int(inside.sum())
    return float(np.clip((k + 1) / (n + 2), 0.05, 0.95))


def _allocate(m1: float, p1: float, left: int, delta: float) -> int:
    """The draws for stratum 1 (of ``left``) that minimise the expected width of the stratified interval:
    m1·(upper − lower of k1 = p1·n1 failures in n1) + m0·(upper of no failure in n0), with the bounds of
    :data:`SPLIT`. Allocation chosen before the draws (from the guide's data only) keeps the interval valid."""
    n1 = np.arange(1, left)
    k1 = np.clip(np.round(p1 * n1), 0, n1)
    (a1, b1), (a0, b0) = (s * delta for s in SPLIT[0]), (s * delta for s in SPLIT[1])
    low1, high1 = binomial_bounds(k1, n1, a1, b1)
    high0 = binomial_bounds(0, left - n1, a0, b0)[1]
    return int(n1[np.argmin(m1 * (high1 - low1) + (1 - m1) * high0)])


def estimate_risk(f: Callable[[np.ndarray], Any], dist: ThetaDistribution, method: str, *, eps_safe_m: float,
                  tau: float = TAU, delta: float = DELTA, max_evals: int = 1024, seed: int = 0,
                  guide_evals: int = GUIDE_EVALS, guide_fraction: float = GUIDE_FRACTION,
                  share: float | None = SHARE) -> RiskResult:
    """p_fail of ``f`` (a batched objective: ``(n, d)`` θ → values or :class:`~vbl_robust.search.evaluations.Evaluations`)
    under ``dist`` by ``method`` (:data:`RISK_METHODS`; module docstring), spending at most ``max_evals``."""
    if method not in RISK_METHODS:
        raise ValueError(f"risk method must be one of {', '.join(RISK_METHODS)}, got {method!r}")
    if not 2 <= max_evals <= MAX_EVALS:
        raise ValueError(f"--max-evals must be in [2, {MAX_EVALS}] for risk, got {max_evals}")
    if (share is not None and not 0.0 < share < 1.0) or not 0.0 < guide_fraction <= 1.0:
        raise ValueError(f"share must be in (0, 1) and guide_fraction in (0, 1], got {share}, {guide_fraction}")
    rng = np.random.default_rng(seed)
    if method == "mc":
        return _mc(f, dist, eps_safe_m, tau, delta, max_evals, rng)
    return _guided(f, dist, eps_safe_m, tau, delta, max_evals, rng, seed, guide_evals, guide_fraction, share)
