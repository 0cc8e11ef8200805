"""The statistics behind every number vbl-robust reports with its uncertainty: exact intervals of rates, exact
paired tests, the three-way verdict of a claim, and what "no breach found" after k uniform points is worth.

All results are typed (frozen dataclasses), never string-keyed dicts. The computations are scipy's
(``scipy.stats.binomtest`` and its exact Clopper–Pearson interval); this module only names them and fixes the
conventions:

- *Level*: every interval is two-sided at ``level`` (default 95 %); every test is two-sided at ``ALPHA`` (5 %).
- *Exact*: Clopper–Pearson intervals cover the true rate with probability ≥ ``level`` for every n and rate (they
  are conservative); the McNemar test is the exact binomial test on the discordant pairs.
- *Rates in %*: :class:`Rate` holds counts and gives percentages; the interval bounds are percentages too.

This module imports nothing of the package, so every floor may use it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

__all__ = [
    "ALPHA", "LEVEL", "ClaimVerdict", "Interval", "Paired", "Rate", "RiskVerdict", "SequentialTest", "Stratum",
    "binomial_bounds", "breach_fraction_bound", "claim_verdict", "clopper_pearson", "holm", "paired", "rate", "risk_verdict",
    "stratified_interval",
]

#: Two-sided confidence level of every interval.
LEVEL = 0.95
#: Two-sided significance level of every test behind a claim's verdict (:func:`claim_verdict`).
ALPHA = 0.05


@dataclass(frozen=True)
class Interval:
    """A two-sided confidence interval ``[low, high]`` at ``level``, by ``method``."""

    low: float
    high: float
    level: float = LEVEL
    method: str = "Clopper-Pearson"

    def __contains__(self, value: float) -> bool:
        return self.low <= value <= self.high

    @property
    def half_width(self) -> float:
        return (self.high - self.low) / 2.0


def clopper_pearson(k: int, n: int, level: float = LEVEL) -> Interval:
    """Exact (Clopper–Pearson) interval of a binomial proportion with ``k`` successes in ``n`` trials, as
    fractions in [0, 1] (``scipy.stats.binomtest(k, n).proportion_ci(method="exact")``). ``n == 0`` gives the
    uninformative [0, 1]. ``ValueError`` for counts out of range or a level outside (0, 1).

    >>> ci = clopper_pearson(50, 100)
    >>> round(ci.low, 3), round(ci.high, 3)
    (0.398, 0.602)
    """
    from scipy.stats import binomtest

    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if n < 0 or not 0 <= k <= max(n, 0):
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return Interval(0.0, 1.0, level)
    ci = binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method="exact")
    return Interval(float(ci.low), float(ci.high), level)


@dataclass(frozen=True)
class Rate:
    """``k`` of ``n`` items (images, approaches, samples) with a property, e.g. survivors of a box.

    ``pct`` is 100·k/n (NaN for n = 0); ``ci`` its exact interval in % (:func:`clopper_pearson`)."""

    k: int
    n: int
    level: float = LEVEL

    def __post_init__(self) -> None:
        if self.n < 0 or not 0 <= self.k <= max(self.n, 0):
            raise ValueError(f"need 0 <= k <= n, got k={self.k}, n={self.n}")

    @property
    def pct(self) -> float:
        return 100.0 * self.k / self.n if self.n else math.nan

    @property
    def ci(self) -> Interval:
        f = clopper_pearson(self.k, self.n, self.level)
        return Interval(100.0 * f.low, 100.0 * f.high, self.level, f.method)

    def text(self, digits: int = 0, *, percent: bool = True) -> str:
        """``"50 % [40, 60]"``: the rate and its interval, in % (``percent=False``: ``"50 [40, 60]"``, for a table
        whose header names the unit); ``"–"`` for n = 0."""
        if not self.n:
            return "–"
        ci = self.ci
        return f"{self.pct:.{digits}f}{' %' if percent else ''} [{ci.low:.{digits}f}, {ci.high:.{digits}f}]"


def rate(flags: Sequence[bool] | np.ndarray, level: float = LEVEL) -> Rate:
    """The :class:`Rate` of the true values among ``flags``."""
    f = np.asarray(flags, dtype=bool).reshape(-1)
    return Rate(int(f.sum()), int(f.size), level)


@dataclass(frozen=True)
class Paired:
    """Exact McNemar comparison of two boolean outcomes on the *same* items (``a[i]``, ``b[i]``: did item i
    survive with A / with B — two detectors, two searches, a search and the dense grid).

    Attributes: ``n``, ``both``, ``only_a``, ``only_b``, ``neither`` (counts); ``p_value``: under "A and B alike",
    each discordant item is A's with probability ½, so p is the two-sided binomial test of ``only_a`` in
    ``only_a + only_b`` (1.0 without a discordant item). ``gain`` = only_a − only_b: A's advantage in items.
    """

    n: int
    both: int
    only_a: int
    only_b: int
    neither: int
    p_value: float

    @property
    def gain(self) -> int:
        return self.only_a - self.only_b

    @property
    def discordant(self) -> int:
        return self.only_a + self.only_b

    @property
    def rate_a(self) -> Rate:
        return Rate(self.both + self.only_a, self.n)

    @property
    def rate_b(self) -> Rate:
        return Rate(self.both + self.only_b, self.n)


def paired(a: Sequence[bool] | np.ndarray, b: Sequence[bool] | np.ndarray) -> Paired:
    """:class:`Paired` for two equal-length boolean vectors (``ValueError`` otherwise)."""
    from scipy.stats import binomtest

    a, b = np.asarray(a, bool), np.asarray(b, bool)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"paired: need two equal-length 1-D vectors, got shapes {a.shape} and {b.shape}")
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    p = float(binomtest(only_a, only_a + only_b, 0.5).pvalue) if only_a + only_b else 1.0
    return Paired(int(a.size), int(np.sum(a & b)), only_a, only_b, int(np.sum(~a & ~b)), min(p, 1.0))


class ClaimVerdict(StrEnum):
    """The verdict on a claim; the first three are what a paired test says of a directional claim ("A survives
    more than B", "A finds more breaches"), the others what a claim made of several parts can add (the paper's
    claims page, in this order).

    - ``HOLDS``: significant (p < ``ALPHA``) in the claimed direction; every part of a claim holds.
    - ``PARTLY``: some parts of a claim hold, none is contradicted.
    - ``TIE``: no significant difference either way — the data cannot tell A from B.
    - ``CONTRADICTED``: significant the other way.
    - ``FAILS``: the claim does not hold (no part holds, none is a tie).
    - ``NOT_RUN``: nothing to judge it on yet (its experiment was not run, or cannot be computed).
    """

    HOLDS = "holds"
    PARTLY = "partly"
    TIE = "tie"
    CONTRADICTED = "contradicted"
    FAILS = "does not hold"
    NOT_RUN = "not run yet"


def claim_verdict(test: Paired, *, a_better: bool = True, alpha: float = ALPHA) -> ClaimVerdict:
    """The verdict of the claim "A beats B" (``a_better``; "B beats A" when False) from the exact McNemar
    ``test`` of A against B, at two-sided significance ``alpha``. "Beats" means more items with the outcome the
    vectors encode (a claim about *fewer* survivors passes the vectors of breaches, or ``a_better=False``)."""
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if test.p_value >= alpha or test.gain == 0:
        return ClaimVerdict.TIE
    return ClaimVerdict.HOLDS if (test.gain > 0) == a_better else ClaimVerdict.CONTRADICTED


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm–Bonferroni adjusted p-values of a family of tests, in the given order: the k-th smallest of m is
    multiplied by m − k + 1, made non-decreasing, capped at 1; rejecting where the adjusted p < α keeps the
    family-wise error rate ≤ α. Written here because scipy has only false-discovery-rate adjustments
    (``scipy.stats.false_discovery_control``) and statsmodels is not a dependency.

    >>> holm([0.01, 0.04, 0.03])
    [0.03, 0.06, 0.06]
    """
    p = np.asarray(p_values, dtype=np.float64)
    m = p.size
    order = np.argsort(p, kind="stable")
    adjusted = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out = np.empty(m)
    out[order] = adjusted
    return [round(float(v), 15) for v in out]


def breach_fraction_bound(k: int, level: float = LEVEL) -> float:
    """Upper bound on the breached fraction of Θ (its volume under the sampling distribution) when ``k``
    independent uniform points all missed it: the fraction is below 1 − (1 − level)^(1/k) at confidence ``level``
    (the exact binomial bound for 0 successes in k; ≈ 3/k at 95 %, the "rule of three"). ``k = 0`` gives 1.

    >>> round(breach_fraction_bound(100), 4)
    0.0295
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if k < 0:
        raise ValueError(f"k must be >= 0, got {k}")
    return 1.0 if k == 0 else float(1.0 - (1.0 - level) ** (1.0 / k))


class RiskVerdict(StrEnum):
    """The verdict on "the failure probability is at most τ, at confidence 1 − δ".

    - ``HOLDS``: the interval's top is ≤ τ.
    - ``VIOLATED``: the interval's bottom is > τ.
    - ``UNDECIDED``: the interval straddles τ (more evaluations would be needed).
    """

    HOLDS = "holds"
    VIOLATED = "violated"
    UNDECIDED = "undecided"


def risk_verdict(ci: Interval, tau: float) -> RiskVerdict:
    """:class:`RiskVerdict` of a failure-probability interval (fractions) against the limit ``tau``."""
    if ci.high <= tau:
        return RiskVerdict.HOLDS
    return RiskVerdict.VIOLATED if ci.low > tau else RiskVerdict.UNDECIDED


@dataclass(frozen=True)
class SequentialTest:
    """A group-sequential test of "p ≤ τ" for Bernoulli outcomes, valid however early it stops.

    The outcomes are looked at after ``looks[0] < looks[1] < …`` of them (e.g. 32, 64, 128, …); at each look the
    exact interval at level 1 − δ/K (K = ``len(looks)``) decides: top ≤ τ → holds, bottom > τ → violated, else go
    on; after the last look it is undecided. By the union bound over the K looks, the probability that any
    reported interval misses p is ≤ δ, so the verdict and the interval at the stopping look are valid at
    confidence 1 − δ (PRoA-style: stop as soon as decided). Written here: scipy has no sequential binomial test.
    """

    tau: float
    delta: float
    looks: tuple[int, ...]

    def __post_init__(self) -> None:
        if not 0.0 <= self.tau < 1.0:
            raise ValueError(f"tau must be in [0, 1), got {self.tau!r}")
        if not 0.0 < self.delta < 1.0:
            raise ValueError(f"delta must be in (0, 1), got {self.delta!r}")
        if not self.looks or any(b <= a for a, b in zip(self.looks, self.looks[1:], strict=False)) or self.looks[0] < 1:
            raise ValueError(f"looks must be increasing positive counts, got {self.looks!r}")

    @classmethod
    def doubling(cls, tau: float, delta: float, max_n: int, first: int = 32) -> SequentialTest:
        """Looks at ``first``, 2·first, 4·first, … and ``max_n`` (the last)."""
        if max_n < 1:
            raise ValueError(f"max_n must be >= 1, got {max_n}")
        looks, n = [], min(first, max_n)
        while n < max_n:
            looks.append(n)
            n *= 2
        return cls(tau, delta, (*looks, max_n))

    @property
    def level(self) -> float:
        """The level of each look's interval, 1 − δ/K."""
        return 1.0 - self.delta / len(self.looks)

    def interval(self, k: int, n: int) -> Interval:
        return clopper_pearson(k, n, self.level)

    def decide(self, k: int, n: int) -> RiskVerdict | None:
        """At a look (``n`` in ``looks``): the verdict, or None to go on (undecided after the last look)."""
        if n not in self.looks:
            raise ValueError(f"{n} outcomes is not a look of this test ({self.looks})")
        v = risk_verdict(self.interval(k, n), self.tau)
        if v is RiskVerdict.UNDECIDED and n != self.looks[-1]:
            return None
        return v


@dataclass(frozen=True)
class Stratum:
    """One stratum of a stratified sample: its probability ``mass`` under the sampling distribution, and ``k``
    failures in ``n`` draws from the distribution restricted to it."""

    mass: float
    k: int
    n: int


def binomial_bounds(k: Any, n: Any, alpha_low: float, alpha_high: float) -> tuple[Any, Any]:
    """One-sided exact (Clopper–Pearson) bounds of a binomial proportion: a lower bound that exceeds p with
    probability ≤ ``alpha_low`` and an upper bound below p with probability ≤ ``alpha_high`` (beta quantiles; 0 for
    k = 0 and 1 for k = n). ``clopper_pearson`` at level 1 − α is the pair with α/2 on each side. ``k`` and ``n``
    may be arrays (broadcast; then the bounds are arrays), e.g. every allocation of a budget at once."""
    from scipy.stats import beta

    k_, n_ = np.asarray(k), np.asarray(n)
    if np.any(n_ < 0) or np.any(k_ < 0) or np.any(k_ > np.maximum(n_, 0)):
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if not (0.0 < alpha_low < 1.0 and 0.0 < alpha_high < 1.0):
        raise ValueError(f"alphas must be in (0, 1), got {alpha_low!r}, {alpha_high!r}")
    low = np.where(k_ > 0, beta.ppf(alpha_low, np.maximum(k_, 1), n_ - k_ + 1), 0.0)
    high = np.where(k_ < n_, beta.ppf(1.0 - alpha_high, k_ + 1, np.maximum(n_ - k_, 1)), 1.0)
    return (float(low), float(high)) if low.ndim == 0 else (low, high)


def stratified_interval(strata: Sequence[Stratum], level: float = LEVEL,
                        split: Sequence[tuple[float, float]] | None = None) -> tuple[float, Interval]:
    """The stratified estimate Σ mass·k/n of a failure probability and a valid interval: each stratum's one-sided
    exact bounds (:func:`binomial_bounds`), weighted by its mass. The error δ = 1 − ``level`` is shared among the 2S
    one-sided bounds by ``split`` (per stratum, the shares of δ of its lower and upper bound, fixed before the draws;
    they sum to 1), by default evenly (δ/(2S) each: Bonferroni, the two-sided exact interval at 1 − δ/S per
    stratum). The masses must sum to 1; a stratum with n = 0 contributes its whole mass to the top."""
    total = sum(s.mass for s in strata)
    if not strata or abs(total - 1.0) > 1e-9 or any(s.mass < 0 for s in strata):
        raise ValueError(f"strata masses must be >= 0 and sum to 1, got {[s.mass for s in strata]}")
    delta = 1.0 - level
    split = [(0.5 / len(strata), 0.5 / len(strata))] * len(strata) if split is None else list(split)
    if len(split) != len(strata) or any(a <= 0 or b <= 0 for a, b in split) or abs(sum(map(sum, split)) - 1) > 1e-9:
        raise ValueError(f"split needs a positive (low, high) share per stratum summing to 1, got {split}")
    est, low, high = 0.0, 0.0, 0.0
    for s, (a, b) in zip(strata, split, strict=True):
        lo, hi = binomial_bounds(s.k, s.n, a * delta, b * delta)
        est += s.mass * (s.k / s.n if s.n else 0.0)
        low += s.mass * lo
        high += s.mass * hi
    method = "stratified Clopper-Pearson (Bonferroni" + (")" if len(set(split)) == 1 else ", δ split fixed in advance)")
    return est, Interval(low, min(high, 1.0), level, method)
