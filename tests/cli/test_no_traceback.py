"""Inputs at the edge of what the options allow end in a result or in one line, never a traceback: the smallest
image size renders (16 px); a strip no runway fits in is refused in one line; a 0-byte store and a store nothing
was run into are refused in one line by every report format."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.scenes.envelopes import fit_margin
from vbl_robust.store.core import ResultStore

runner = CliRunner()


def _one_line(res, code: int) -> str:
    assert res.exit_code == code and "Traceback" not in res.output, res.output
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error")]
    assert len(errors) == 1, res.output
    return errors[0]


def test_the_smallest_image_size_renders(tmp_path):
    for args in (["--n", "6"], ["--sequences", "2", "--frames", "3"]):
        out = tmp_path / "-".join(args)
        res = runner.invoke(app, ["-q", "scenes", *args, "--width", "16", "--height", "16", "--out", str(out)])
        assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["-q", "audit", "--width", "16", "--height", "16", "--oracle", "--n", "2", "--methods",
                              "random", "--max-evals", "4", "--no-landscape", "--workers", "1", "--no-report",
                              "--out", str(tmp_path / "run")])
    assert res.exit_code == 0, res.output
    assert fit_margin(8.0, 16, 16) == 3.75 and fit_margin(8.0, 33, 4096) == 8.0  # unchanged from 33 px up


def test_a_strip_no_runway_fits_in_is_refused_in_one_line(tmp_path):
    line = _one_line(runner.invoke(app, ["scenes", "--n", "2", "--width", "4096", "--height", "16", "--out",
                                         str(tmp_path / "s")]), 2)
    assert "shows the whole runway" in line
    line = _one_line(runner.invoke(app, ["audit", "--width", "2000", "--height", "16", "--oracle", "--n", "1",
                                         "--out", str(tmp_path / "run")]), 2)
    assert "shows the whole runway" in line and not (tmp_path / "run").exists()
    res = runner.invoke(app, ["scenes", "--n", "1", "--width", "100000", "--out", str(tmp_path / "big")])
    assert res.exit_code == 2 and "--width" in res.output and not (tmp_path / "big").exists()


@pytest.mark.parametrize("kind", ["zero-bytes", "no-campaign"])
@pytest.mark.parametrize("fmt", ["html", "md", "csv", "json"])
def test_a_store_with_nothing_in_it_is_refused_by_every_report_format(tmp_path, kind, fmt):
    run = tmp_path / "run"
    run.mkdir()
    if kind == "zero-bytes":
        (run / "results.sqlite").write_bytes(b"")
    else:
        ResultStore(run / "results.sqlite").close()
    line = _one_line(runner.invoke(app, ["report", str(run), "--format", fmt]), 2)
    assert "no campaign" in line
