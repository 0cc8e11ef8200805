import pytest
import typer
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.cli.common import parse_range

runner = CliRunner()


def test_version_and_short_help():
    from importlib.metadata import version

    res = runner.invoke(app, ["--version"])
    assert res.exit_code == 0 and res.output.strip() == f"vbl-robust {version('vbl-robust')}"
    short = runner.invoke(app, ["audit", "-h"])
    assert short.exit_code == 0 and "--roll" in short.output


def test_help_lists_commands():
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0
    for command in ("scenes", "audit", "demo", "reproduce", "report", "bundle", "train", "zones"):
        assert command in res.output, command


@pytest.mark.parametrize(
    "text, symmetric, expected",
    [("15", True, (-15.0, 15.0)), ("0.7,1.4", False, (0.7, 1.4)), ("-5, 10", True, (-5.0, 10.0))],
)
def test_parse_range(text, symmetric, expected):
    assert parse_range(text, name="--roll", symmetric=symmetric) == expected


@pytest.mark.parametrize("text", ["abc", "1,2,3", "0.7", "1.4,0.7", "nan,1", "1,inf"])
def test_parse_range_rejects_with_option_name(text):
    with pytest.raises(typer.BadParameter, match="--contrast"):
        parse_range(text, name="--contrast", symmetric=False)


@pytest.mark.parametrize("text", ["-15", "0"])
def test_a_symmetric_half_width_must_be_positive(text):
    """``--roll -15`` is refused, not read as ±15 (a sign the user typed is never dropped silently)."""
    with pytest.raises(typer.BadParameter, match="half-width must be > 0"):
        parse_range(text, name="--roll", symmetric=True)


def _commands():
    import typer.main

    group = typer.main.get_command(app)
    return group, {name: group.get_command(None, name) for name in group.list_commands(None)}


def test_every_option_has_help_and_flags_show_no_type():
    group, commands = _commands()
    for name, cmd in [("vbl-robust", group), *commands.items()]:
        for p in cmd.params:
            if p.param_type_name == "option":
                assert p.help, f"{name} {p.opts[0]}: no help text"
        res = runner.invoke(app, ["--help"] if cmd is group else [name, "--help"], terminal_width=200)
        assert res.exit_code == 0 and "<bool>" not in res.output, name


def test_quiet_and_verbose_before_or_after_the_command(tmp_path):
    import logging

    from vbl_robust.cli import common

    args = ["--oracle", "--n", "1", "--max-evals", "3", "--roll", "5", "--width", "96", "--height", "96",
            "--methods", "random", "--no-report", "--out"]
    loud = runner.invoke(app, ["audit", *args, str(tmp_path / "a")])
    for i, order in enumerate((["-q", "audit"], ["audit", "-q"])):
        res = runner.invoke(app, [*order, *args, str(tmp_path / f"q{i}")])
        assert res.exit_code == 0, res.output
        assert "survival" in loud.output and "survival" not in res.output  # the table is not printed
    for order in (["-v", "audit", "--help"], ["audit", "-v", "--help"]):
        assert runner.invoke(app, order).exit_code == 0
    res = runner.invoke(app, ["-v", "audit", *args, str(tmp_path / "v")])
    assert res.exit_code == 0 and logging.getLogger().level == logging.INFO
    runner.invoke(app, ["audit", *args, str(tmp_path / "v")])  # the next invocation starts from its own flags
    assert logging.getLogger().level == logging.WARNING and common._GLOBAL == {"quiet": False, "verbose": False}


@pytest.mark.parametrize("args, named", [
    (["audit", "--out", ""], "--out"),
    (["audit", "--out="], "--out"),
    (["risk", "--csv", ""], "--csv"),
    (["report", ""], "an argument"),
])
def test_an_empty_value_is_refused_not_read_as_the_current_directory(tmp_path, monkeypatch, args, named):
    """``--out ""`` became Path("") = "." and the run wrote into the current directory."""
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and f"Invalid value for {named}: an empty value" in res.output, res.output
    assert list(tmp_path.iterdir()) == []


def test_an_os_error_outside_a_campaign_is_one_line_without_the_resume_hint(tmp_path):
    """``zones RUN --out DIR`` was a traceback (IsADirectoryError); a command that stores no jobs says nothing of
    resuming."""
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
    from vbl_robust.store.core import ResultStore

    spec = CampaignSpec("zones-out", (Block(boxes=(roll_box(5),), methods=("georobust",),
                                            budgets=(Budget(max_evals=8),)),), seed=1)
    with ResultStore(tmp_path / "run" / "results.sqlite") as store:
        run_campaign(spec, list(generate(1, seed=0, width=96, height=96)), store, detector=DetectorSpec.oracle(1.0))
    (tmp_path / "dir").mkdir()
    res = runner.invoke(app, ["zones", str(tmp_path / "run"), "--out", str(tmp_path / "dir")])
    # refused before any work since the output places are tried first (cli.common.check_writable)
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert res.output.strip().splitlines()[-1] == f"error: --out {tmp_path / 'dir'}: is a directory"
