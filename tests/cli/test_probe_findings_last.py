"""The adversarial probe's last bad and weak findings (issue 59), each as the user meets it: refused in one line
before any work and leaving what exists as it was, or reported for what it is.

- ``zones --lipschitz 1,2`` on a 1-D run (exit 0 with nothing zoned: only the searches that keep cells checked it);
- a refused ``merge`` of another campaign rewrote the target's lock file;
- ``scenes --out`` over an existing dataset overwrote it; ``--out`` naming a file failed with exit 1;
- ``train --init`` naming a 0-byte ``.pt`` stopped in ultralytics with a traceback;
- an ``--out`` with a 300-character name stopped at the run's first write (exit 1), an unwritable ``--csv`` at its end;
- ``truth --out RUN`` printed a line of work before its refusal;
- ``report --format md`` of a risk run was refused, of a run in progress said nothing of the jobs to come, and
  ``report`` exited 0 with a row that contradicts its own evaluations left out.
"""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()
SMALL = ["--oracle", "--n", "2", "--max-evals", "4", "--roll", "5", "--workers", "1", "--no-report", "-q"]


def _error(res) -> str:
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].lower().startswith("error"), res.output
    return lines[0]


def _tree(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def run1d(tmp_path_factory) -> Path:
    """A finished 1-D oracle run: two images, random search only (no job keeps cells to zone)."""
    out = tmp_path_factory.mktemp("run") / "run"
    res = runner.invoke(app, ["audit", *SMALL, "--methods", "random", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def risk_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("risk") / "risk"
    res = runner.invoke(app, ["risk", "--oracle", "--n", "1", "--roll", "5", "--methods", "mc", "--max-evals", "8",
                              "--workers", "1", "--no-report", "-q", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def test_zones_refuses_a_lipschitz_vector_that_fits_no_box_of_the_run(run1d):
    line = _error(runner.invoke(app, ["zones", str(run1d), "--lipschitz", "1,2"]))
    assert "2 numbers" in line and "1 parameter(s) (roll_deg)" in line
    assert runner.invoke(app, ["zones", str(run1d), "--lipschitz", "1"]).exit_code == 0


def test_a_refused_merge_leaves_the_target_as_it_was(run1d, risk_run, tmp_path):
    into = tmp_path / "merged"
    assert runner.invoke(app, ["merge", str(run1d), "--into", str(into)]).exit_code == 0
    before = _tree(into)
    assert "results.sqlite.lock" in before
    assert "another campaign" in _error(runner.invoke(app, ["merge", str(risk_run), "--into", str(into)]))
    assert _tree(into) == before
    fresh = tmp_path / "fresh"
    _error(runner.invoke(app, ["merge", str(run1d), str(risk_run), "--into", str(fresh)]))
    assert not fresh.exists()


def test_scenes_never_writes_over_an_existing_directory_or_file(tmp_path):
    ds = tmp_path / "ds"
    assert runner.invoke(app, ["-q", "scenes", "--n", "1", "--width", "64", "--height", "64", "--out",
                               str(ds)]).exit_code == 0
    before = _tree(ds)
    assert "not empty" in _error(runner.invoke(app, ["scenes", "--n", "1", "--width", "64", "--height", "64",
                                                     "--seed", "5", "--out", str(ds)]))
    assert _tree(ds) == before
    file = tmp_path / "f.txt"
    file.write_text("x")
    assert "is a file" in _error(runner.invoke(app, ["scenes", "--n", "1", "--out", str(file)]))
    assert file.read_text() == "x"


def test_train_refuses_an_init_checkpoint_that_is_no_checkpoint(tmp_path):
    empty = tmp_path / "empty.pt"
    empty.write_bytes(b"")
    out = tmp_path / "train"
    line = _error(runner.invoke(app, ["train", "--n-train", "2", "--n-val", "1", "--epochs", "1", "--imgsz", "32",
                                      "--init", str(empty), "--trust-model", "--out", str(out)]))
    assert "--init" in line and "not a PyTorch checkpoint" in line and not out.exists()


def test_an_output_the_run_could_not_write_is_refused_before_it(tmp_path):
    long = tmp_path / ("L" * 300)
    assert "300 bytes long" in _error(runner.invoke(app, ["audit", *SMALL, "--methods", "random", "--out",
                                                          str(long)]))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    out = tmp_path / "r"
    line = _error(runner.invoke(app, ["audit", *SMALL, "--methods", "random", "--out", str(out), "--csv",
                                      str(blocker / "jobs.csv")]))
    assert line.startswith("error: --csv") and "cannot write there" in line and not out.exists()


def test_truth_into_the_run_itself_is_refused_in_one_line(run1d):
    before = _tree(run1d)
    assert "is the run itself" in _error(runner.invoke(app, ["truth", str(run1d), "--counts", "3", "--out",
                                                             str(run1d)]))
    assert _tree(run1d) == before


def test_a_risk_runs_markdown_is_its_failure_probability(risk_run):
    res = runner.invoke(app, ["report", str(risk_run), "--format", "md"])
    assert res.exit_code == 0, res.output
    assert "| estimator | box |" in res.stdout and "| mc | ±5° | 1 |" in res.stdout


def _edited(run: Path, copy: Path, sql: str) -> Path:
    """A copy of ``run`` with ``sql`` executed on its store."""
    shutil.copytree(run, copy)
    with sqlite3.connect(copy / "results.sqlite") as con:
        con.execute(sql)
    return copy


def test_the_markdown_of_a_partial_run_says_how_much_is_stored(run1d, tmp_path):
    part = _edited(run1d, tmp_path / "part", "UPDATE runs SET jobs_total = jobs_total + 5, status = 'running'")
    res = runner.invoke(app, ["report", str(part), "--format", "md"])
    assert res.exit_code == 0, res.output
    assert "Run in progress: a run is still writing this store; 3 of 8 planned jobs stored so far" in res.stdout
    with sqlite3.connect(part / "results.sqlite") as con:
        con.execute("UPDATE runs SET status = 'killed'")
    assert "Incomplete: 3 of 8 planned jobs stored (the last run killed)" in runner.invoke(
        app, ["report", str(part), "--format", "md"]).stdout
    assert "planned jobs" not in runner.invoke(app, ["report", str(run1d), "--format", "md"]).stdout


def test_report_exits_1_when_a_row_contradicts_its_own_evaluations(run1d, tmp_path):
    edited = _edited(run1d, tmp_path / "edited",
                     "UPDATE jobs SET worst_m = 1.0 WHERE rowid = (SELECT min(rowid) FROM jobs WHERE role = 'main')")
    res = runner.invoke(app, ["report", str(edited), "--format", "md"])
    assert res.exit_code == 1 and "inconsistent — not used" in res.output, res.output
    assert runner.invoke(app, ["report", str(run1d), "--format", "md"]).exit_code == 0


def test_a_refusal_quoting_line_breaks_stays_one_line():
    """A damaged model's exception can quote its bytes, line breaks included (a random-bytes .pt did): the
    refusal shows them escaped."""
    import typer

    from vbl_robust.cli.common import fail

    one = typer.Typer()

    @one.command()
    def refuse() -> None:
        fail("invalid load key, '\n'\r\x0b\x1c\x85\u2028 end")

    res = runner.invoke(one, [])
    assert res.exit_code == 2 and len(res.output.splitlines()) == 1, repr(res.output)
    assert res.output.startswith("error: invalid load key, '\\n'\\r") and res.output.rstrip().endswith("end")
