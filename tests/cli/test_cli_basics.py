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
