"""Bad findings of the adversarial probe (benchmarks/adversarial_probes.py): nonsense that ran to exit 0 is
refused in one line before anything is created — a stray comma in ``--methods``, an angle range beyond ±180°."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.space import ParameterBox

runner = CliRunner()
SMALL = ["--oracle", "--n", "1", "--max-evals", "2", "--no-landscape", "--workers", "1", "--no-report", "-q",
         "--width", "96", "--height", "96"]


def _refused(res, *words: str) -> None:
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip() and not ln.startswith(("Usage: ", "Try '"))]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert all(w in lines[0] for w in words), res.output


@pytest.mark.parametrize("methods", ["random,", ",random", "random,,georobust"])
def test_a_stray_comma_in_methods_is_refused(tmp_path, methods):
    _refused(runner.invoke(app, ["audit", "--methods", methods, "--out", str(tmp_path / "r"), *SMALL]), "--methods")
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("args", [["--roll", "720"], ["--roll", "-200,10"], ["--perturb", "yaw_deg=-1e300,1e300"],
                                  ["--perturb", "pitch_deg=0,181"]])
def test_an_angle_beyond_180_degrees_is_refused(tmp_path, args):
    _refused(runner.invoke(app, ["audit", *args, "--out", str(tmp_path / "r"), *SMALL]), "180")
    assert not (tmp_path / "r").exists()


def test_the_library_refuses_an_angle_box_beyond_180_degrees():
    Perturbation(ParameterBox({"roll_deg": (-180.0, 180.0)}))  # the whole circle is a box
    for name in ("roll_deg", "pitch_deg", "yaw_deg"):
        with pytest.raises(ValueError, match=name):
            Perturbation(ParameterBox({name: (-10.0, 190.0)}))


def _tree(d):
    return {p.relative_to(d): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_a_run_on_other_pixels_under_the_same_sample_names_is_refused_and_changes_nothing(tmp_path):
    """The same synthetic samples at another size have the same ids and another fingerprint: their rows would sit
    beside the stored ones under the same names (2 images reported as 4)."""
    out = tmp_path / "run"
    args = ["audit", "--oracle", "--n", "1", "--max-evals", "2", "--roll", "5", "--methods", "random",
            "--no-landscape", "--workers", "1", "--no-report", "-q", "--out", str(out)]
    assert runner.invoke(app, [*args, "--width", "96", "--height", "96"]).exit_code == 0
    before = _tree(out)
    _refused(runner.invoke(app, [*args, "--width", "128", "--height", "128"]), "synth_", "another size")
    assert _tree(out) == before


def test_a_name_that_is_not_utf8_is_refused_in_one_line(tmp_path):
    import os
    import subprocess
    import sys

    bad = os.fsencode(str(tmp_path)) + b"/run\xff\xfe"
    vbl = os.path.join(os.path.dirname(sys.executable), "vbl-robust")
    res = subprocess.run([vbl, "audit", *SMALL, "--roll", "5", "--methods", "random", "--out", bad],
                         capture_output=True, env={**os.environ, "VBL_ROBUST_WORKERS": "1"})
    out = res.stdout.decode() + res.stderr.decode("utf-8", "replace")
    assert res.returncode == 2 and "Traceback" not in out and "not valid UTF-8" in out, out
    assert not os.path.exists(bad)


def test_an_integer_of_5000_digits_is_refused_in_one_line(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("seed: " + "9" * 5000 + "\n")
    _refused(runner.invoke(app, ["audit", *SMALL, "--config", str(cfg), "--out", str(tmp_path / "r")]), "--config")
    _refused(runner.invoke(app, ["audit", *SMALL, "--method-option", "random.batch_size=" + "9" * 5000,
                                 "--out", str(tmp_path / "r")]), "--method-option")
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("methods", ["mc,", ",guided", "mc,,guided"])
def test_risk_refuses_a_stray_comma_in_methods(tmp_path, methods):
    _refused(runner.invoke(app, ["risk", "--oracle", "--n", "1", "--roll", "5", "--methods", methods,
                                 "--out", str(tmp_path / "r"), "--workers", "1", "-q", "--no-report"]), "--methods")
    assert not (tmp_path / "r").exists()


def test_risk_mc_alone_is_not_refused_over_guided_options_default(tmp_path):
    res = runner.invoke(app, ["risk", "--oracle", "--n", "1", "--roll", "5", "--methods", "mc", "--max-evals", "16",
                              "--width", "96", "--height", "96", "--out", str(tmp_path / "r"), "--workers", "1", "-q",
                              "--no-report"])
    assert res.exit_code == 0, res.output
    _refused(runner.invoke(app, ["risk", "--oracle", "--n", "1", "--roll", "5", "--methods", "mc,guided",
                                 "--max-evals", "16", "--out", str(tmp_path / "g"), "--workers", "1", "-q"]),
             "--guide-evals")


def test_zones_refuses_a_store_that_holds_no_campaign(tmp_path):
    (tmp_path / "results.sqlite").write_bytes(b"")
    _refused(runner.invoke(app, ["zones", str(tmp_path)]), "no campaign")


@pytest.mark.parametrize("option", ["--time-budgets", "--eval-budgets"])
def test_reproduce_refuses_a_stray_comma_in_budgets(tmp_path, option):
    _refused(runner.invoke(app, ["reproduce", "runtime-1d", option, "1,", "--images", "1", "--oracle",
                                 "--workers", "1", "--out", str(tmp_path / "r")]), option)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("value", ["5,", ",5", "1,,2"])
def test_a_stray_comma_in_lipschitz_is_refused(tmp_path, value):
    _refused(runner.invoke(app, ["audit", *SMALL, "--lipschitz", value, "--out", str(tmp_path / "r")]),
             "--lipschitz")
    _refused(runner.invoke(app, ["zones", str(tmp_path / "none"), "--lipschitz", value]), "--lipschitz")


def test_reproduce_resume_from_a_directory_without_packed_stores_is_refused(tmp_path):
    (tmp_path / "b" / "spatial-1d").mkdir(parents=True)
    _refused(runner.invoke(app, ["reproduce", "spatial-1d", "--images", "1", "--oracle", "--workers", "1",
                                 "--resume-from", str(tmp_path / "b"), "--out", str(tmp_path / "r")]), "--resume-from")
    assert not (tmp_path / "r").exists()


def test_merging_a_run_into_itself_is_refused_and_changes_nothing(tmp_path):
    out = tmp_path / "run"
    assert runner.invoke(app, ["audit", *SMALL, "--roll", "5", "--methods", "random", "--out", str(out)]).exit_code == 0
    before = _tree(out)
    _refused(runner.invoke(app, ["merge", str(out), "--into", str(out)]), "itself")
    _refused(runner.invoke(app, ["merge", str(out / "results.sqlite"), "--into", str(out)]), "itself")
    assert _tree(out) == before


@pytest.mark.parametrize("lr0", ["-1", "nan", "0"])
def test_train_refuses_a_learning_rate_before_making_its_directory(tmp_path, lr0):
    _refused(runner.invoke(app, ["train", "--n-train", "2", "--n-val", "1", "--epochs", "1", "--imgsz", "32",
                                 "--lr0", lr0, "--out", str(tmp_path / "t")]), "--lr0")
    assert not (tmp_path / "t").exists()


def test_zones_refuses_a_plot_directory_that_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    _refused(runner.invoke(app, ["zones", str(tmp_path / "none"), "--plot", str(tmp_path / "f")]), "--plot")
    assert (tmp_path / "f").read_text() == "x"


def test_reproduce_refuses_an_infinite_grid_step(tmp_path):
    _refused(runner.invoke(app, ["reproduce", "spatial-1d", "--grid-step", "inf", "--images", "1", "--oracle",
                                 "--workers", "1", "--out", str(tmp_path / "r")]), "--grid-step")
    assert not (tmp_path / "r").exists()
