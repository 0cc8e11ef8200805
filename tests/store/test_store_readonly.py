"""Reading a run never writes its store: report, zones and the Markdown tables open it read-only."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.store import schema
from vbl_robust.store.core import ResultStore

runner = CliRunner()


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("ro") / "run"
    res = runner.invoke(app, ["audit", "--oracle", "--n", "2", "--max-evals", "6", "--roll", "5", "--width", "96",
                              "--height", "96", "--methods", "georobust,random", "--no-report", "--quiet",
                              "--workers", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _copy_store_alone(run_dir, dest):
    """Only the database file (no -wal / -shm beside it), checkpointed first."""
    con = sqlite3.connect(run_dir / "results.sqlite")
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    con.close()
    dest.mkdir()
    shutil.copy(run_dir / "results.sqlite", dest / "results.sqlite")
    return dest


def _state(d):
    return sorted(p.name for p in d.iterdir()), hashlib.sha256((d / "results.sqlite").read_bytes()).hexdigest()


def test_reading_commands_leave_the_store_untouched(run_dir, tmp_path):
    d = _copy_store_alone(run_dir, tmp_path / "copy")
    before = _state(d)
    for args in (["report", str(d), "--format", "md"], ["zones", str(d), "--estimate", "--format", "md"],
                 ["report", str(d), "--out", str(tmp_path / "html")]):
        res = runner.invoke(app, args)
        assert res.exit_code == 0, (args, res.output)
    assert _state(d) == before  # no new file beside it (no -wal, -shm, lock), the same bytes


def test_an_older_layout_is_read_in_memory_and_not_migrated_on_disk(run_dir, tmp_path):
    d = _copy_store_alone(run_dir, tmp_path / "old")
    con = sqlite3.connect(d / "results.sqlite")
    con.execute(f"PRAGMA user_version = {schema.SCHEMA_VERSION - 1}")
    con.commit()
    con.close()
    before = _state(d)
    with ResultStore.open_existing(d) as st:
        assert st.readonly and st.count() > 0
    assert _state(d) == before
    con = sqlite3.connect(d / "results.sqlite")
    assert con.execute("PRAGMA user_version").fetchone()[0] == schema.SCHEMA_VERSION - 1


def test_a_read_only_store_refuses_writes(run_dir, tmp_path):
    d = _copy_store_alone(run_dir, tmp_path / "w")
    with ResultStore.open_existing(d) as st, pytest.raises(sqlite3.OperationalError, match="readonly|read-only|query"):
        st.forget_failed()
    with ResultStore.open_existing(d, readonly=False) as st:  # the writer still can
        st.forget_failed()
