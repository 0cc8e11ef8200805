import pytest
import typer
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.cli.common import parse_range

runner = CliRunner()


def test_help_lists_commands():
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0
    assert "scenes" in res.output


@pytest.mark.parametrize(
    "text, symmetric, expected",
    [("15", True, (-15.0, 15.0)), ("-15", True, (-15.0, 15.0)), ("0.7,1.4", False, (0.7, 1.4)), ("-5, 10", True, (-5.0, 10.0))],
)
def test_parse_range(text, symmetric, expected):
    assert parse_range(text, name="--roll", symmetric=symmetric) == expected


@pytest.mark.parametrize("text", ["abc", "1,2,3", "0.7"])
def test_parse_range_rejects_with_option_name(text):
    with pytest.raises(typer.BadParameter, match="--contrast"):
        parse_range(text, name="--contrast", symmetric=False)
