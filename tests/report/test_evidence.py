"""The report's evidence section and evidence.json: per box over every method together, counts and exact intervals
recomputed here from the stored rows."""

import json

import pytest
from typer.testing import CliRunner

from vbl_robust.analysis.breach import breach_kind, survived
from vbl_robust.analysis.readoff import main_rows
from vbl_robust.cli import app
from vbl_robust.constants import BreachKind
from vbl_robust.stats import Rate, breach_fraction_bound
from vbl_robust.store.core import ResultStore


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ev") / "run"
    res = CliRunner().invoke(app, [
        "audit", "--out", str(out), "--n", "4", "--roll", "10", "--methods", "random,georobust", "--max-evals", "8",
        "--no-landscape", "--workers", "1", "--oracle", "--oracle-noise", "0.5", "--width", "320", "--height", "320",
        "--quiet"])
    assert res.exit_code == 0, res.output
    return out


def test_evidence_counts_images_over_every_method_with_exact_intervals(run):
    ev = json.loads((run / "evidence.json").read_text())
    with ResultStore.open_existing(run) as st:
        spec = st.spec()
        rows = main_rows(st, spec)
    eps = spec.settings.eps_safe_m
    [box] = ev["boxes"]
    ids = {r.sample_id for r in rows}
    breached = {r.sample_id for r in rows if not survived(r, eps)}
    silent = {r.sample_id for r in rows if breach_kind(r, eps) is BreachKind.MISLEADING}
    assert box["images"] == len(ids) == 4 and box["survivors"] == len(ids - breached)
    assert 0 < box["survivors"] < 4  # the run has both kinds of image (the test would be vacuous otherwise)
    assert box["misleading"] == len(silent) and box["flagged"] == len(breached - silent)
    assert box["survival_ci"] == pytest.approx([Rate(box["survivors"], 4).ci.low, Rate(box["survivors"], 4).ci.high])
    assert box["ranges"] == {"roll_deg": [-10.0, 10.0]} and box["methods"] == ["random", "georobust"]
    assert box["evaluations"] == sum(r.nfev for r in rows)
    random_ok = [r for r in rows if r.method == "random" and r.sample_id not in breached]
    assert box["residual_bound"] == pytest.approx(max(breach_fraction_bound(r.nfev) for r in random_ok))
    # the worst cases: one per breached image, misleading ones first, each kind by its error (largest first)
    rank = {"misleading": 0, None: 1, "flagged": 2}
    order = [(rank[w["kind"]], -w["worst_m"]) for w in ev["worst"]]
    assert len(order) == len(breached) == ev["breached"] and order == sorted(order)
    page = (run / "report.html").read_text()
    assert "Safe where, and how sure" in page and "survival % [95 % CI]" in page
