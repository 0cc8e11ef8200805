"""The command line's shared options and request objects (:mod:`vbl_robust.cli.options`, :mod:`vbl_robust.cli.requests`)
and a run's provenance configuration = the command's parameters (:func:`vbl_robust.cli.config.run_config`)."""

import subprocess
import sys
from pathlib import Path
from typing import get_args

import typer
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.cli import options as o
from vbl_robust.cli.config import run_config
from vbl_robust.cli.requests import BoxRequest, DetectorRequest, ImagesRequest, RunRequest
from vbl_robust.store.core import ResultStore

runner = CliRunner()


def test_the_command_line_imports_no_heavy_library():
    # `vbl-robust --help` must stay instant: what takes time to import is imported inside the commands
    code = ("import sys, vbl_robust.cli; print(sorted(m for m in ('torch', 'scipy', 'cv2', 'matplotlib', "
            "'ultralytics', 'pymap3d', 'rich', 'yaml', 'importlib.metadata') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout
    assert out.strip() == "[]"


def test_a_variant_keeps_the_option_and_changes_only_what_it_names():
    shared = get_args(o.MaxEvals)[1]
    kind, info = get_args(o.variant(o.MaxEvals, int, min=2, help="other"))
    assert kind is int and (info.default, info.param_decls) == (shared.default, shared.param_decls)
    assert (info.min, info.max, info.help) == (2, shared.max, "other")
    assert shared.min == 0 and shared.help != "other"  # the shared declaration is untouched
    try:
        o.variant(o.MaxEvals, hepl="typo")
    except TypeError as exc:
        assert "hepl" in str(exc)
    else:
        raise AssertionError("a misspelt attribute must be refused")


def test_a_request_takes_its_fields_from_the_parameters_by_name():
    params = {"n": 3, "seed": 7, "lard": None, "width": 64, "height": 48, "roll": "5", "contrast": None,
              "perturb": ["blur_px"], "workers": 2, "wait": True, "model": None, "oracle": True, "out": Path("x")}
    assert ImagesRequest.of(params) == ImagesRequest(3, 7, None, 64, 48)
    assert ImagesRequest.of(params, n=None).n is None  # a command whose option has another name (reproduce --images)
    assert BoxRequest.of(params) == BoxRequest("5", None, ["blur_px"])
    run = RunRequest.of(params)  # the fields a command has no option for keep their defaults
    assert (run.workers, run.wait, run.clock, run.executor, run.allow_unmeasured) == (2, True, "auto", "local", False)
    assert DetectorRequest.of(params).oracle and DetectorRequest.of(params).design == "auto"
    assert BoxRequest.of(params).spec().box.names == ("roll_deg", "blur_px")


def test_the_run_config_is_the_commands_parameters_with_what_the_run_resolved(tmp_path):
    probe = typer.Typer()
    seen = {}

    @probe.command()
    def cmd(out: o.Out = Path("runs/x"), n: o.Images = None, design: o.Design = "auto", quiet: o.Quiet = False,
            config: o.Config = None) -> None:
        seen.update(run_config("cmd", n=4))

    res = runner.invoke(probe, ["--out", str(tmp_path / "r"), "--detector", "single", "-q"])
    assert res.exit_code == 0, res.output
    # keys as the options are spelt (--detector, not the parameter's name), paths as text, the resolved n;
    # what only shapes the output (--quiet, --config) is not recorded
    assert seen == {"command": "cmd", "detector": "single", "n": 4, "out": str(tmp_path / "r")}
    assert run_config("outside", n=1) == {"command": "outside", "n": 1}  # no command running: what it was given


def test_an_audits_provenance_keeps_its_keys_and_records_every_parameter(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "1", "--roll", "5", "--methods", "random,grid",
                              "--max-evals", "4", "--no-landscape", "--no-report", "--oracle", "--width", "96",
                              "--height", "96", "--workers", "1", "--quiet"])
    assert res.exit_code == 0, res.output
    with ResultStore.open_existing(out) as store:
        user = store.runs()[-1].provenance.config["user"]
    # the keys the hand-built configuration had, with the same values
    assert {k: user[k] for k in ("command", "n", "seed", "lard", "roll", "contrast", "methods", "max_evals",
                                 "max_seconds", "early_stop", "lipschitz", "pnp", "width", "height")} == {
        "command": "audit", "n": 1, "seed": 0, "lard": None, "roll": "5", "contrast": None,
        "methods": ["random", "grid"], "max_evals": 4, "max_seconds": None, "early_stop": True, "lipschitz": None,
        "pnp": "ippe_lm", "width": 96, "height": 96}
    # and every other option as config.yaml records it
    assert user["detector"] == "auto" and user["oracle"] is True and user["out"] == str(out)
    assert "quiet" not in user and "config" not in user
