"""Failure probability (vbl-robust risk): the θ distribution, the two estimators' intervals against a known p_fail
(coverage over seeds, unbiasedness), the sequential stop, pooling, and the command end to end."""

import csv
import math

import numpy as np
import pytest
from scipy.stats import norm
from typer.testing import CliRunner

from vbl_robust.analysis.risk import pooled_risk
from vbl_robust.campaigns.work import risk_payload
from vbl_robust.cli import app
from vbl_robust.risk import Marginal, ThetaDistribution, estimate_risk, parse_dist
from vbl_robust.space import ParameterBox

EPS = 1000.0
BOX = ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.5, 2.0)})


def band(x):
    """Fails on roll ∈ (9, 10.5) at any contrast, and wherever contrast > 1.9: p = 1.5/30 + 0.1/1.5 − overlap."""
    r, c = x[:, 0], x[:, 1]
    return np.where(((r > 9.0) & (r < 10.5)) | (c > 1.9), 4000.0, 100.0 + 20.0 * np.abs(r))


P_BAND = 1.5 / 30 + 0.1 / 1.5 - (1.5 / 30) * (0.1 / 1.5)


def test_the_distribution_draws_where_it_says_and_knows_its_masses():
    d = ThetaDistribution.over(BOX, {"roll_deg": ("normal", 0.0, 5.0)})
    rng = np.random.default_rng(0)
    x = d.sample(200_000, rng)
    assert (x >= BOX.lower).all() and (x <= BOX.upper).all()
    lo, hi = np.array([[2.0, 0.5], [-15.0, 1.5]]), np.array([[6.0, 1.0], [-5.0, 2.0]])
    inside = [np.mean(np.all((x >= a) & (x <= b), axis=1)) for a, b in zip(lo, hi, strict=True)]
    assert d.mass(lo, hi) == pytest.approx(inside, abs=0.004)
    # the truncated normal's own mass, computed from scipy's normal directly
    z = norm(0, 5)
    expected = (z.cdf(6) - z.cdf(2)) / (z.cdf(15) - z.cdf(-15)) * (0.5 / 1.5)
    assert d.mass(lo[:1], hi[:1])[0] == pytest.approx(expected, rel=1e-9)
    # a draw restricted to a rectangle stays in it
    y = d.sample(1000, rng, lo[0], hi[0])
    assert (y >= lo[0]).all() and (y <= hi[0]).all()


def test_bad_distributions_are_refused_in_one_line():
    assert parse_dist(["roll_deg=normal:0,5", "contrast=uniform"]) == {"roll_deg": ("normal", 0.0, 5.0)}
    for item, msg in (("roll_deg=gauss:0,5", "expected NAME=uniform or NAME=normal"),
                      ("roll_deg=normal:0", "expected NAME=normal:MEAN,SD"),
                      ("roll_deg=normal:0,-1", "SD > 0"), ("roll_deg=uniform:1", "uniform takes no arguments")):
        with pytest.raises(ValueError, match=msg):
            parse_dist([item])
    with pytest.raises(ValueError, match="not a parameter of the box"):
        ThetaDistribution.over(BOX, {"pitch_deg": ("normal", 0.0, 1.0)})
    with pytest.raises(ValueError, match="no mass"):
        Marginal("normal", 0.0, 1.0, mu=100.0, sigma=0.01)


@pytest.mark.parametrize("method", ["mc", "guided"])
def test_the_intervals_cover_the_true_failure_probability(method):
    """Over 60 seeds the interval covers the known p in at least 55 (nominal ≥ 95 %: P(≤ 54 of 60) < 1 %); the
    estimates average to p (an unbiased estimator, within 4 standard errors)."""
    d = ThetaDistribution.over(BOX)
    runs = [estimate_risk(band, d, method, eps_safe_m=EPS, tau=0.01, max_evals=256, seed=s) for s in range(60)]
    covered = sum(r.ci.low <= P_BAND <= r.ci.high for r in runs)
    assert covered >= 55, covered
    est = np.array([r.p_fail for r in runs])
    assert abs(est.mean() - P_BAND) < 4 * est.std(ddof=1) / math.sqrt(len(est)) + 1e-9
    assert all(r.evaluations <= 256 for r in runs)
    if method == "guided":  # it found the band: two strata, the hot one dense in failures
        hot = [r.strata[0] for r in runs if len(r.strata) == 2]
        assert len(hot) >= 50 and np.mean([s.k / s.n for s in hot]) > 5 * P_BAND


def test_monte_carlo_stops_as_soon_as_the_verdict_is_decided():
    d = ThetaDistribution.over(BOX)
    always = estimate_risk(lambda x: np.full(len(x), 5000.0), d, "mc", eps_safe_m=EPS, tau=0.01, max_evals=1024)
    assert always.verdict == "violated" and always.evaluations == 32 and always.ci.low > 0.01
    never = estimate_risk(lambda x: np.full(len(x), 10.0), d, "mc", eps_safe_m=EPS, tau=0.01, max_evals=1024)
    assert never.verdict == "holds" and never.evaluations == 1024 and never.ci.high <= 0.01
    unsure = estimate_risk(band, d, "mc", eps_safe_m=EPS, tau=P_BAND, max_evals=128)
    assert unsure.verdict == "undecided" and unsure.evaluations == 128


def test_failed_evaluations_count_as_failures():
    d = ThetaDistribution.over(BOX)
    r = estimate_risk(lambda x: np.full(len(x), np.nan), d, "mc", eps_safe_m=EPS, max_evals=64)
    assert r.p_fail == 1.0 and r.verdict == "violated"


def test_pooled_rates_and_the_command_end_to_end(tmp_path):
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["risk", "--out", str(out), "--n", "3", "--max-evals", "96", "--guide-evals", "32",
                                   "--oracle", "--oracle-noise", "1", "--width", "320", "--height", "320", "--roll",
                                   "30", "--dist", "roll_deg=normal:0,10", "--workers", "1", "--csv",
                                   str(tmp_path / "r.csv")])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    assert len(rows) == 6 and {r["method"] for r in rows} == {"mc", "guided"}
    for r in rows:
        lo, p, hi = float(r["ci_low"]), float(r["p_fail"]), float(r["ci_high"])
        assert 0 <= lo <= p <= hi <= 1 and int(r["evaluations"]) <= 96 and r["risk_verdict"] in ("holds", "violated",
                                                                                                 "undecided")
    assert "mc: 3 images, p_fail pooled" in res.output and "guided: 3 images" in res.output
    page = (out / "report.html").read_text()
    assert "Failure probability under the θ distribution" in page and "roll_deg normal(0, 10) truncated" in page
    from vbl_robust.store.core import ResultStore

    with ResultStore.open_existing(out) as st:
        pooled = {p.method: p for p in pooled_risk(st.jobs(kind="risk", with_points=True))}
    mc_rows = [r for r in rows if r["method"] == "mc"]
    n_min = min(int(r["evaluations"]) for r in mc_rows)
    assert pooled["mc"].images == 3 and pooled["mc"].ci.low <= pooled["mc"].p_fail <= pooled["mc"].ci.high
    assert pooled["mc"].p_fail * 3 * n_min == pytest.approx(round(pooled["mc"].p_fail * 3 * n_min))
    for bad, msg in ((["--dist", "roll_deg=normal:0"], "--dist roll_deg=normal:0"), (["--tau", "1.5"], "--tau"),
                     (["--methods", "mc,mc"], "--methods mc,mc"), (["--guide-evals", "2000"], "--guide-evals")):
        res = CliRunner().invoke(app, ["risk", "--out", str(tmp_path / "bad"), "--oracle", *bad])
        assert res.exit_code == 2 and msg in res.output, res.output


def test_the_guided_draws_are_split_by_the_expected_width_and_the_split_is_stored():
    """The allocation puts few draws in a hot stratum of tiny mass and many in one that is large and uncertain; the
    δ split travels with the result (payload) and the pooled interval reads it back."""
    from vbl_robust.risk import _allocate

    few, many = _allocate(0.01, 0.5, 400, 0.05), _allocate(0.6, 0.5, 400, 0.05)
    assert 1 <= few < 100 < many < 400
    r = estimate_risk(band, ThetaDistribution.over(BOX), "guided", eps_safe_m=EPS, max_evals=256, seed=3)
    strata = risk_payload(r, 0.01, 0.05, ThetaDistribution.over(BOX))["risk"]["strata"]
    assert [(s["share_low"], s["share_high"]) for s in strata] == [(0.25, 0.25), (0.05, 0.45)]
    assert 256 - 64 <= sum(s["n"] for s in strata) < r.evaluations <= 256  # the guide spent at most 64
