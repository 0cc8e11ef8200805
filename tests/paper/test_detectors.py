"""The claims compared across detectors (``vbl-robust bundle ROOT --detector LABEL=DIR``): two "detectors" — the
oracle with 1 px and with 30 px of corner noise — run on the same tiny experiments; the table reads each one's
nominal survival off its PnP validation, pairs it against the first, and puts each claim's verdict side by side."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.paper.detectors import detector_profile, detectors_html, detectors_markdown

runner = CliRunner()
LABEL = "noisy <b>|"


def _runs(root: Path, noise: str) -> Path:
    common = ["--oracle", "--oracle-noise", noise, "--workers", "1", "--no-report", "-q"]
    for args in (["pnp-validation", "--images", "3"],
                 ["spatial-2d", "--images", "1", "--max-evals", "6", "--no-landscape"]):
        res = runner.invoke(app, ["reproduce", *args, *common, "--out", str(root / args[0])])
        assert res.exit_code == 0, res.output
    return root


@pytest.fixture(scope="module")
def roots(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("detectors")
    return {"exact": _runs(base / "exact", "1"), LABEL: _runs(base / "noisy", "30")}


def test_each_detectors_nominal_survival_is_read_off_its_pnp_validation(roots):
    exact, noisy = (detector_profile(k, v) for k, v in roots.items())
    assert (exact.nominal.k, exact.nominal.n) == (3, 3)  # 1 px: every pose within ε_safe
    assert noisy.nominal.n == 3 and noisy.nominal.k < 3 and noisy.corner_px_median > 10 > exact.corner_px_median
    assert exact.ids == noisy.ids and "oracle" in exact.identity


def test_the_table_pairs_each_detector_with_the_first_and_sets_the_claims_side_by_side(roots):
    text = detectors_markdown(roots)
    rows = [ln for ln in text.splitlines() if ln.startswith("| ")]
    detector_rows = [r for r in rows if r.startswith(("| exact |", "| noisy &lt;b&gt;\\| |"))]
    assert len(detector_rows) == 2 and "reference" in detector_rows[0]
    assert "McNemar p = " in detector_rows[1] and "of 3" in detector_rows[1]
    spatial = next(r for r in rows if r.startswith("| spatial-2d |"))
    assert "images survive every method" in spatial and "discordant of 1" in spatial
    assert next(r for r in rows if r.startswith("| distance-profile |")).count("not run yet") == 2
    assert "<b>" not in text and "<b>" not in detectors_html(roots) and "&lt;b&gt;" in detectors_html(roots)


def test_bundle_compares_the_detectors_and_refuses_a_malformed_item(roots, tmp_path):
    out = tmp_path / "bundle"
    res = runner.invoke(app, ["-q", "bundle", str(roots["exact"]), "--out", str(out), "--detector",
                              f"{LABEL}={roots[LABEL]}", "--detector-label", "exact"])
    assert res.exit_code == 0, res.output
    assert (out / "detectors.md").read_text() == detectors_markdown(roots)
    assert 'id="detectors"' in (out / "index.html").read_text()
    inside = tmp_path / "inside"  # a detector's bundle under the page's directory is linked, by a relative path
    (inside / "noisy run").mkdir(parents=True)
    (inside / "noisy run" / "index.html").write_text("<p>x</p>")
    page = detectors_html({"exact": roots["exact"], LABEL: inside / "noisy run"}, inside)
    assert '<a href="noisy%20run/index.html">noisy &lt;b&gt;|</a>' in page
    assert "<a href" not in detectors_html(roots, inside)  # roots outside the page's directory: no link
    for item, words in ((str(roots[LABEL]), "expected LABEL=DIR"), (f"x={tmp_path / 'none'}", "not a directory"),
                        (f"exact={roots[LABEL]}", "given twice")):
        res = runner.invoke(app, ["bundle", str(roots["exact"]), "--out", str(tmp_path / "b2"), "--detector", item,
                                  "--detector-label", "exact"])
        assert res.exit_code == 2 and words in res.output and len(res.output.strip().splitlines()) == 1, res.output
        assert not (tmp_path / "b2").exists()
