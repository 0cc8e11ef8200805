"""Kill a real running campaign with SIGKILL and rerun it: nothing committed is lost, nothing is duplicated."""

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
N_SAMPLES = 3
N_JOBS = N_SAMPLES * 2 * 2  # samples x boxes x methods of campaign_helpers.kill_campaign_spec


def start(out: Path, *extra: str, n: int = N_SAMPLES) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, str(HERE / "campaign_helpers.py"), str(out), str(n), "0.1", *extra],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def wait_for_rows(proc: subprocess.Popen, out: Path, n: int) -> None:
    deadline = time.monotonic() + 120
    while len(committed(out)) < n:
        assert proc.poll() is None, f"campaign ended before it could be killed: {proc.stdout.read().decode()[-2000:]}"
        assert time.monotonic() < deadline, "campaign made no progress"
        time.sleep(0.05)


def committed(out: Path) -> dict[str, float]:
    if not out.exists():
        return {}
    con = sqlite3.connect(out, timeout=30)
    try:
        return dict(con.execute("SELECT key, worst_m FROM jobs").fetchall())
    except sqlite3.OperationalError:  # schema not created yet
        return {}
    finally:
        con.close()


@pytest.mark.slow
def test_sigkill_mid_run_then_rerun_loses_nothing_and_duplicates_nothing(tmp_path):
    out = tmp_path / "results.sqlite"
    proc = start(out)
    wait_for_rows(proc, out, 3)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    before = committed(out)
    assert 3 <= len(before) < N_JOBS, "the kill must land mid-run"

    # the rerun is the same campaign in this process (the kill needed a process of its own; the rerun does not)
    from campaign_helpers import main

    main(str(out), N_SAMPLES, 0.1)
    after = committed(out)
    assert len(after) == N_JOBS
    assert all(after[k] == v for k, v in before.items())  # committed rows untouched
    con = sqlite3.connect(out)
    assert con.execute("SELECT COUNT(*), COUNT(DISTINCT key) FROM jobs").fetchone() == (N_JOBS, N_JOBS)
    runs = con.execute("SELECT status, jobs_skipped, jobs_done, finished_at, seconds FROM runs ORDER BY run_id").fetchall()
    last_job = con.execute("SELECT max(finished_at) FROM jobs WHERE run_id = 1").fetchone()[0]
    # the killed run never recorded its end: the next run closed it at its last stored job
    assert runs[0][:4] == ("killed", 0, len(before), last_job) and 0 < runs[0][4] < 180
    assert runs[1][:3] == ("finished", len(before), N_JOBS - len(before))


@pytest.mark.slow
def test_sigterm_ends_the_run_as_an_interruption_with_its_wall_time(tmp_path):
    """``kill PID`` (SIGTERM) under the CLI's handler: the run records its end (status, jobs, seconds) before the
    process exits, so a bundle's wall time and the run list stay true."""
    out = tmp_path / "results.sqlite"
    proc = start(out, "term")
    wait_for_rows(proc, out, 2)
    proc.send_signal(signal.SIGTERM)
    output = proc.communicate(timeout=60)[0].decode()
    assert proc.returncode != 0 and "KeyboardInterrupt" in output
    kept = committed(out)
    con = sqlite3.connect(out)
    status, done, seconds = con.execute("SELECT status, jobs_done, seconds FROM runs").fetchone()
    con.close()
    assert status == "interrupted" and done == len(kept) and 2 <= done < N_JOBS and seconds > 0


@pytest.mark.slow
def test_workers_that_cannot_start_end_the_run_in_one_line_and_the_process_exits(tmp_path):
    """Every worker fails to build its detector: the run ends "incomplete" with the workers' reason in one line (no
    traceback), and the process exits although the task queue still holds more than a pipe's worth of samples."""
    proc = start(tmp_path / "results.sqlite", "workers-fail", n=150)
    try:
        out = proc.communicate(timeout=120)[0].decode()
    finally:
        proc.kill()
    assert proc.returncode == 0, out[-2000:]
    assert "status=incomplete done=0" in out
    assert "a worker could not start: RuntimeError: no model in this worker" in out
    assert "Traceback" not in out
