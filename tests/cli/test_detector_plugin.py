"""A door for any detector (``--detector-plugin MODULE:FACTORY`` or ``FILE.py:FACTORY``): a plug-in runs audit,
risk and reproduce with the options a user gets; it is refused in one line when it is not a detector or fails on
the run's first image; an exception inside it during a run is *not measured*, never a breach; its identity (name,
source SHA-256, the weights digest the user gives) is in the store; from a --config file it needs --trust-model."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import WORKERS_ENV
from vbl_robust.cli import app
from vbl_robust.digest import file_sha256
from vbl_robust.store.core import ResultStore

runner = CliRunner()
HELPERS = Path(__file__).with_name("plugin_helpers.py")
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "predict_plugin.py"
SMALL = ["--n", "2", "--width", "320", "--height", "320", "--quiet"]


@pytest.fixture(autouse=True)
def _default_workers(monkeypatch):
    monkeypatch.delenv(WORKERS_ENV, raising=False)


def _plugin(factory: str) -> list[str]:
    return ["--detector-plugin", f"{HELPERS}:{factory}"]


def _rows(out):
    with ResultStore(out / "results.sqlite", readonly=True) as st:
        return st.jobs(with_trace=False), st.campaign()


@pytest.mark.slow
def test_a_plugin_runs_audit_risk_and_reproduce_with_the_default_options(tmp_path):
    digest = "ab" * 32
    out = tmp_path / "audit"
    res = runner.invoke(app, ["audit", *_plugin("noisy_corners"), "--plugin-digest", digest, *SMALL,
                              "--max-evals", "6", "--out", str(out)])
    assert res.exit_code == 0, res.output
    rows, camp = _rows(out)
    assert {r.method for r in rows if r.role == "main"} == {"georobust-av", "random", "apgd"}  # APGD too
    assert all(r.measured for r in rows)
    ident = camp.detector
    assert ident["kind"] == "plugin" and ident["factory"] == f"{HELPERS}:noisy_corners"
    assert ident["sha256"] == file_sha256(HELPERS) and ident["options"] == {"weights_sha256": digest}
    html = (out / "report.html").read_text()
    assert "plugin" in html and file_sha256(HELPERS)[:12] in html

    out = tmp_path / "risk"
    # one image: the plug-in in worker processes is the audit's above
    res = runner.invoke(app, ["risk", *_plugin("noisy_corners"), "--n", "1", *SMALL[2:], "--max-evals", "96",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert all(r.measured for r in _rows(out)[0])

    out = tmp_path / "reproduce"
    res = runner.invoke(app, ["reproduce", "spatial-1d", *_plugin("noisy_corners"), "--images", "1", "--width", "320",
                              "--height", "320", "--max-evals", "3", "--grid-step", "0", "--no-landscape",
                              "--no-report", "--quiet", "--out", str(out)])
    assert res.exit_code == 0, res.output
    rows = _rows(out)[0]
    assert rows and all(r.measured for r in rows) and "apgd" in {r.method for r in rows}


@pytest.mark.parametrize("factory, words", [
    ("not_a_detector", "is not a detector: it lacks detect(context), uses_pixels, differentiable"),
    ("raising_factory", "raising_factory() raised OSError: weights not found"),
    ("missing_name", "has no callable 'missing_name'"),
    ("exploding", "detector error on the run's first image (synth_s0_000000): RuntimeError: the plug-in's model "
                  "exploded; nothing was run or stored"),
])
def test_a_plugin_that_is_not_a_detector_is_refused_before_the_run(factory, words, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", *_plugin(factory), *SMALL, "--max-evals", "4", "--methods", "random",
                              "--out", str(out)])
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and words in errors[0] and "Traceback" not in res.output
    assert not (out / "results.sqlite").exists()


def test_an_exception_inside_a_plugin_during_the_run_is_not_measured(tmp_path):
    """Past the first image's check (here: skipped by the library API), the plug-in's exceptions are detector
    errors: jobs not measured, exit 1 — never breaches."""
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box

    spec = CampaignSpec("audit", (Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=3),)),))
    det = DetectorSpec.plugin(f"{HELPERS}:exploding", trust=True)
    with ResultStore(tmp_path / "results.sqlite") as st:
        s = run_campaign(spec, generate(2, seed=0, width=128, height=128), st, detector=det, precheck=False)
        rows = st.jobs(with_trace=False)
    assert s.not_measured == 2 and all(r.reason == "detector error: RuntimeError: the plug-in's model exploded"
                                       for r in rows)
    res = runner.invoke(app, ["report", str(tmp_path), "--format", "json"])
    assert res.exit_code == 1 and "2 of 2 jobs not measured" in res.stderr
    assert json.loads(res.stdout)[0]["images"] == 0


def test_a_plugin_from_a_config_file_needs_consent_typed(tmp_path):
    marker = tmp_path / "imported"
    plugin = tmp_path / "touching.py"
    plugin.write_text(f"open({str(marker)!r}, 'w').close()\n\ndef make():\n    raise SystemExit(9)\n")
    config = tmp_path / "run.yaml"
    config.write_text(f"detector-plugin: {plugin}:make\n")
    res = runner.invoke(app, ["audit", "--config", str(config), *SMALL, "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "comes from a --config file" in res.output, res.output
    assert not marker.exists()  # never imported
    config.write_text(f"detector-plugin: {plugin}:make\ntrust-model: true\n")
    res = runner.invoke(app, ["audit", "--config", str(config), *SMALL, "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "--trust-model: give it on the command line" in res.output, res.output
    assert not marker.exists()


def test_plugin_options_are_checked_in_one_line(tmp_path):
    for args, words in ((["--detector-plugin", "no colon"], "expected MODULE:FACTORY"),
                        (["--detector-plugin", "nowhere.py:make"], "no file nowhere.py"),
                        ([*_plugin("noisy_corners"), "--plugin-digest", "xyz"], "64 hex digits"),
                        (["--plugin-digest", "ab" * 32], "--plugin-digest needs --detector-plugin"),
                        ([*_plugin("noisy_corners"), "--oracle"], "--detector-plugin and --oracle are exclusive")):
        res = runner.invoke(app, ["audit", *args, *SMALL, "--out", str(tmp_path / "run")])
        assert res.exit_code == 2 and words in res.output, (args, res.output)


@pytest.mark.slow
def test_the_example_plugin_of_the_how_to_runs(tmp_path):
    """examples/predict_plugin.py (the how-to's plug-in: ultralytics' own predictor on the shipped weights) runs
    an audit; it has no gradient, so the default methods are refused naming the black-box ones."""
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--detector-plugin", f"{EXAMPLE}:make_detector", *SMALL, "--max-evals", "4",
                              "--roll", "5", "--no-landscape", "--out", str(out)])
    assert res.exit_code == 2 and "--methods apgd: method unfit" in res.output, res.output
    # one image: a plug-in in worker processes is test_a_plugin_runs_audit_risk_and_reproduce_with_the_default_options's
    res = runner.invoke(app, ["audit", "--detector-plugin", f"{EXAMPLE}:make_detector", "--n", "1", *SMALL[2:],
                              "--max-evals", "4", "--roll", "5", "--no-landscape", "--methods", "georobust-av,random",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    rows = _rows(out)[0]
    assert len(rows) == 2 and all(r.measured for r in rows)
