"""vbl_robust.stats: exact intervals, the paired test, claim verdicts, the zero-breach bound — against known values
and against their defining property (exact coverage computed from the binomial distribution)."""

import math

import numpy as np
import pytest
from scipy.stats import binom, binomtest

from vbl_robust.stats import (
    ClaimVerdict,
    Paired,
    Rate,
    breach_fraction_bound,
    claim_verdict,
    clopper_pearson,
    holm,
    paired,
    rate,
)


def test_clopper_pearson_matches_the_published_values():
    # the values quoted in issue 45: 50 % and 10 % of 100 images
    ci = Rate(50, 100).ci
    assert (round(ci.low, 1), round(ci.high, 1)) == (39.8, 60.2)
    ci = Rate(10, 100).ci
    assert (round(ci.low, 1), round(ci.high, 1)) == (4.9, 17.6)
    # the ends: 0 of n has low 0 and high 1 - (alpha/2)^(1/n); n of n the mirror image
    ci = clopper_pearson(0, 20)
    assert ci.low == 0.0 and ci.high == pytest.approx(1 - 0.025 ** (1 / 20))
    assert clopper_pearson(20, 20).low == pytest.approx(0.025 ** (1 / 20)) and clopper_pearson(20, 20).high == 1.0
    assert clopper_pearson(0, 0) == clopper_pearson(0, 0, 0.95) and (clopper_pearson(0, 0).low, clopper_pearson(0, 0).high) == (0.0, 1.0)


@pytest.mark.parametrize("n", [5, 17, 60])
def test_clopper_pearson_covers_at_least_its_level_for_every_rate(n):
    """Exact coverage P_p(p ∈ CI(K, n)), K ~ Bin(n, p), summed over k; a Wald interval fails this at small n."""
    cis = [clopper_pearson(k, n) for k in range(n + 1)]
    for p in np.linspace(0.001, 0.999, 199):
        cover = sum(binom.pmf(k, n, p) for k, ci in enumerate(cis) if ci.low <= p <= ci.high)
        assert cover >= 0.95 - 1e-9, (n, p, cover)


def test_rate_counts_and_text():
    r = rate([True, False, True, True])
    assert (r.k, r.n, r.pct) == (3, 4, 75.0) and r.text() == f"75 % [{r.ci.low:.0f}, {r.ci.high:.0f}]"
    assert math.isnan(Rate(0, 0).pct) and Rate(0, 0).text() == "–"
    assert Rate(1, 2).text(1, percent=False) == f"50.0 [{Rate(1, 2).ci.low:.1f}, {Rate(1, 2).ci.high:.1f}]"
    with pytest.raises(ValueError, match="0 <= k <= n"):
        Rate(5, 4)
    with pytest.raises(ValueError, match="level"):
        clopper_pearson(1, 2, level=1.0)


def test_paired_counts_the_discordant_items_and_tests_them():
    a = [True] * 50 + [True] * 7 + [False] * 2 + [False] * 1
    b = [True] * 50 + [False] * 7 + [True] * 2 + [False] * 1
    c = paired(a, b)
    assert (c.n, c.both, c.only_a, c.only_b, c.neither, c.gain) == (60, 50, 7, 2, 1, 5)
    assert c.p_value == pytest.approx(binomtest(7, 9).pvalue) and 0.05 < c.p_value < 0.2
    assert (c.rate_a.k, c.rate_b.k) == (57, 52)
    # swapping the sides swaps the counts, not the p-value; identical vectors differ nowhere
    r = paired(b, a)
    assert (r.only_a, r.only_b, r.gain) == (2, 7, -5) and r.p_value == pytest.approx(c.p_value)
    assert paired(a, a).p_value == 1.0 and paired(a, a).gain == 0
    assert paired([True] * 30, [False] * 30).p_value < 1e-6
    with pytest.raises(ValueError, match="equal-length"):
        paired([True, False], [True])


def test_claim_verdicts_follow_the_test_and_its_direction():
    strong = Paired(n=40, both=0, only_a=12, only_b=0, neither=28, p_value=binomtest(12, 12).pvalue)
    weak = Paired(n=40, both=30, only_a=3, only_b=1, neither=6, p_value=binomtest(3, 4).pvalue)
    assert claim_verdict(strong) is ClaimVerdict.HOLDS
    assert claim_verdict(strong, a_better=False) is ClaimVerdict.CONTRADICTED
    assert claim_verdict(weak) is ClaimVerdict.TIE and claim_verdict(weak, a_better=False) is ClaimVerdict.TIE
    assert claim_verdict(Paired(10, 5, 0, 0, 5, 1.0)) is ClaimVerdict.TIE
    # the threshold is the test's: a p just under alpha decides, just over does not
    edge = Paired(n=20, both=0, only_a=6, only_b=0, neither=14, p_value=binomtest(6, 6).pvalue)  # 0.03125
    assert claim_verdict(edge, alpha=0.05) is ClaimVerdict.HOLDS and claim_verdict(edge, alpha=0.01) is ClaimVerdict.TIE


@pytest.mark.parametrize("k", [1, 10, 100, 1000])
def test_the_zero_breach_bound_is_the_exact_binomial_bound(k):
    b = breach_fraction_bound(k)
    # a breached fraction at the bound gives no breach in k points with probability exactly 5 %
    assert (1 - b) ** k == pytest.approx(0.05)
    # ... and any larger fraction less often: the bound is where "no breach in k" stops being plausible
    assert (1 - min(1.0, 1.01 * b)) ** k < 0.05
    assert breach_fraction_bound(0) == 1.0 and round(breach_fraction_bound(100), 4) == 0.0295


def test_holm_adjusts_a_family_of_tests():
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.5]) == [0.5] and holm([]) == []
    assert holm([0.001, 0.9, 0.2, 0.02]) == pytest.approx([0.004, 0.9, 0.4, 0.06])
    # never below the raw p, never above 1, order of the input kept
    raw = list(np.random.default_rng(0).uniform(0, 0.3, 12))
    adj = holm(raw)
    assert all(a >= r for a, r in zip(adj, raw, strict=True)) and max(adj) <= 1.0


def test_one_sided_bounds_match_the_exact_interval_and_a_split_moves_delta_to_the_upper_bound():
    from vbl_robust.stats import Stratum, binomial_bounds, clopper_pearson, stratified_interval

    for k, n in ((0, 50), (3, 50), (50, 50), (17, 120)):
        ci = clopper_pearson(k, n, 0.95)
        assert binomial_bounds(k, n, 0.025, 0.025) == pytest.approx((ci.low, ci.high), abs=1e-12)
    strata = [Stratum(0.1, 30, 60), Stratum(0.9, 0, 200)]
    _, even = stratified_interval(strata, 0.95)
    a, b = clopper_pearson(30, 60, 0.975), clopper_pearson(0, 200, 0.975)
    assert (even.low, even.high) == pytest.approx((0.1 * a.low + 0.9 * b.low, 0.1 * a.high + 0.9 * b.high))
    _, split = stratified_interval(strata, 0.95, [(0.25, 0.25), (0.05, 0.45)])
    # the empty stratum's upper bound gets 0.45 δ instead of 0.25 δ: a lower top, the same bottom (k = 0: 0)
    assert split.low == pytest.approx(even.low) and split.high < even.high
    assert 0.9 * (1 - (0.45 * 0.05) ** (1 / 200)) + 0.1 * binomial_bounds(30, 60, 0.0125, 0.0125)[1] == \
        pytest.approx(split.high)
    for bad in ([(0.5, 0.5)], [(0.25, 0.25), (0.25, 0.3)], [(0.0, 0.5), (0.25, 0.25)]):
        with pytest.raises(ValueError, match="split"):
            stratified_interval(strata, 0.95, bad)


def test_a_split_interval_still_covers_at_its_level():
    """Exact coverage of the split stratified interval over every outcome of two strata (enumerated, not sampled):
    ≥ 95 % for several true rates."""
    from scipy.stats import binom

    from vbl_robust.stats import Stratum, stratified_interval

    m1, n1, n0 = 0.15, 20, 30
    for p1, p0 in ((0.5, 0.0), (0.3, 0.02), (0.9, 0.1), (0.05, 0.05)):
        p = m1 * p1 + (1 - m1) * p0
        cover = 0.0
        for k1 in range(n1 + 1):
            for k0 in range(n0 + 1):
                _, ci = stratified_interval([Stratum(m1, k1, n1), Stratum(1 - m1, k0, n0)], 0.95,
                                            [(0.25, 0.25), (0.05, 0.45)])
                if ci.low <= p <= ci.high:
                    cover += binom.pmf(k1, n1, p1) * binom.pmf(k0, n0, p0)
        assert cover >= 0.95, (p1, p0, cover)
