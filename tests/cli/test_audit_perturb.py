"""``vbl-robust audit --perturb NAME=LO,HI``: any combination of families is a box (issue 15 part 2)."""

import json
import sqlite3

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.cli.common import parse_perturb
from vbl_robust.perturb.registry import PERTURBATIONS

runner = CliRunner()
SMALL = ["--oracle", "--oracle-noise", "0.5", "--width", "128", "--height", "128", "--quiet", "--no-report",
         "--no-landscape"]


def test_perturb_adds_families_to_the_box(tmp_path):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--n", "1", "--roll", "5", "--perturb",
                              "pitch_deg=-3,3", "--perturb", "blur_px", "--methods", "random", "--max-evals", "4",
                              *SMALL])
    assert res.exit_code == 0, res.output
    (spec,) = sqlite3.connect(tmp_path / "results.sqlite").execute("SELECT spec_json FROM campaign").fetchone()
    box = json.loads(spec)["blocks"][0]["boxes"][0]["box"]
    assert box["bounds"] == {"roll_deg": [-5.0, 5.0], "pitch_deg": [-3.0, 3.0], "blur_px": [0.0, 2.0]}
    assert box["units"]["blur_px"] == "px"


def test_parse_perturb_defaults_and_order():
    assert parse_perturb(["haze=0,0.3", "gamma"]) == {"haze": (0.0, 0.3), "gamma": PERTURBATIONS["gamma"].default}
    assert parse_perturb(None) == {}


@pytest.mark.parametrize("args, message", [
    (["--perturb", "fog=0,1"], "--perturb fog=0,1: unknown perturbation 'fog'; known perturbations: roll_deg, "),
    (["--perturb", "haze=0,x"], "--perturb haze=0,x: expected haze=LOWER,UPPER"),
    (["--perturb", "haze=0.5,0.1"], "LOWER < UPPER"),
    (["--perturb", "haze=0,1.5"], "--perturb haze=0,1.5: haze must lie within [0, 1]"),
    (["--perturb", "blur_px=-1,2"], "blur_px must lie within [0, inf]"),
    (["--perturb", "gamma", "--perturb", "gamma=1,2"], "gamma is given more than once"),
    (["--contrast", "0.8,1.2", "--perturb", "contrast=0.5,2"], "give the contrast range once"),
    (["--roll", "none"], "at least one of --roll, --contrast, --perturb"),
])
def test_perturb_user_errors_are_one_line(tmp_path, args, message):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--n", "1", "--width", "128", "--height", "128", *args])
    assert res.exit_code == 2 and message in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1
