"""Inputs that were taken silently, or stopped more than they should: each is refused in one line, or fails only
its own sample — ``--roll 5,``, ``zones --threshold -1``, a fifth runway corner, two distributions for one
parameter, an image name the file system refuses; and a risk run's ``report --format csv|json`` says what it
holds."""

from __future__ import annotations

import csv
import io
import json
import shutil

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.risk import parse_dist

runner = CliRunner()
SMALL = ["--oracle", "--max-evals", "4", "--no-landscape", "--workers", "1", "--no-report", "-q"]


@pytest.fixture(scope="module")
def lard(tmp_path_factory):
    out = tmp_path_factory.mktemp("lard") / "lard"
    res = runner.invoke(app, ["-q", "scenes", "--n", "2", "--width", "96", "--height", "96", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _error(res) -> str:
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    lines = [ln for ln in res.output.splitlines() if ln.lower().startswith("error")]
    assert len(lines) == 1, res.output
    return lines[0]


@pytest.mark.parametrize("roll", ["5,", ",5", "5,,6", " , "])
def test_a_range_with_an_empty_value_is_refused(tmp_path, roll):
    assert "--roll" in _error(runner.invoke(app, ["audit", "--roll", roll, "--out", str(tmp_path / "r"), *SMALL]))
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf"])
def test_zones_refuses_a_threshold_that_is_no_error_bound(tmp_path, value):
    assert "--threshold" in _error(runner.invoke(app, ["zones", str(tmp_path), "--threshold", value]))


def test_two_distributions_for_one_parameter_contradict_each_other():
    for items in (["roll_deg=uniform", "roll_deg=normal:0,1"], ["roll_deg=normal:0,1", "roll_deg=normal:0,1"]):
        with pytest.raises(ValueError, match="roll_deg is given twice"):
            parse_dist(items)
    with pytest.raises(ValueError, match="pitch_deg is not a parameter of the box"):
        parse_dist(["pitch_deg=uniform"], names=("roll_deg",))
    assert parse_dist(["roll_deg=uniform", "contrast=normal:1,0.1"], names=("roll_deg", "contrast")) == {
        "contrast": ("normal", 1.0, 0.1)}


def test_a_fifth_runway_corner_is_refused(lard, tmp_path):
    bad = tmp_path / "lard"
    shutil.copytree(lard, bad)
    db_path = next(bad.glob("*.json"))
    db = json.loads(db_path.read_text())
    for runways in db.values():
        for entry in runways.values():
            entry["E"] = dict(entry["D"])
    db_path.write_text(json.dumps(db))
    line = _error(runner.invoke(app, ["audit", "--lard", str(bad), "--out", str(tmp_path / "r"), *SMALL]))
    assert "corner(s) E beside A, B, C, D" in line and not (tmp_path / "r").exists()


def test_an_image_name_the_file_system_refuses_fails_its_own_sample_only(lard, tmp_path):
    """A 304-character file name (longer than a file system's 255): the run is refused before it starts, as for any
    missing image; with --allow-unmeasured that image's job is not measured and the other is run."""
    long = tmp_path / "lard"
    shutil.copytree(lard, long)
    table = long / "metadata.csv"
    first = sorted((long / "images").iterdir())[0].name
    name = "images/" + "z" * 293 + ".png"
    assert len(name) == 304
    table.write_text(table.read_text().replace(f"images/{first}", name))
    res = runner.invoke(app, ["audit", "--lard", str(long), "--methods", "random", "--out", str(tmp_path / "r"),
                              *SMALL])
    assert "input unavailable" in _error(res) and not (tmp_path / "r").exists()
    res = runner.invoke(app, ["audit", "--lard", str(long), "--methods", "random", "--out", str(tmp_path / "r"),
                              "--allow-unmeasured", *SMALL])
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    assert "2 new jobs" in res.output and "1 not measured" in res.output, res.output


def test_a_risk_runs_summary_is_its_failure_probability_per_estimator(lard, tmp_path):
    out = tmp_path / "risk"
    res = runner.invoke(app, ["risk", "--lard", str(lard), "--methods", "mc,guided", "--max-evals", "16",
                              "--guide-evals", "4", "--oracle", "--workers", "1", "--no-report", "-q", "--out",
                              str(out)])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(io.StringIO(runner.invoke(app, ["report", str(out), "--format", "csv"]).stdout)))
    assert [r["method"] for r in rows] == ["mc", "guided"]
    assert all(r["images"] == "2" and float(r["p_fail_ci_low"]) <= float(r["p_fail"]) <= float(r["p_fail_ci_high"])
               and int(r["holds"]) + int(r["violated"]) + int(r["undecided"]) == 2 for r in rows)
    records = json.loads(runner.invoke(app, ["report", str(out), "--format", "json"]).stdout)
    assert [r["method"] for r in records] == ["mc", "guided"] and records[0]["ci_level"] == 0.95
