"""Workers never outlive their parent, even when it dies while they start (before they have imported torch, the
detector or their own arguments): the parent is killed with SIGKILL as soon as its two workers exist."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")


def _stat(pid: int) -> tuple[str, int] | None:
    """``(state, parent PID)`` of ``pid``, or None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text.rsplit(")", 1)[1].split()
    return fields[0], int(fields[1])


def _workers(parent: int) -> list[int]:
    """The spawned multiprocessing workers among ``parent``'s children (not its resource tracker)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        st = _stat(int(entry.name))
        if st is None or st[1] != parent:
            continue
        try:
            cmd = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if b"spawn_main" in cmd:
            found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    st = _stat(pid)
    return st is not None and st[0] not in ("Z", "X")


@pytest.mark.slow
def test_workers_die_when_their_parent_is_killed_during_their_start_up(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    parent = subprocess.Popen([sys.executable, str(HERE / "start_up_campaign.py"), str(tmp_path / "r.sqlite")],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 300
        while len(workers) < 2:
            assert parent.poll() is None, parent.stdout.read().decode()[-2000:]
            assert time.monotonic() < deadline, "the campaign started no workers"
            workers = _workers(parent.pid)
            time.sleep(0.01)
        parent.send_signal(signal.SIGKILL)  # the workers are starting: their interpreters have just begun
        parent.wait(timeout=30)
        deadline = time.monotonic() + 30
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        survivors = [w for w in workers if _alive(w)]
        assert not survivors, f"workers {survivors} outlived their parent"
    finally:
        parent.kill()
        for w in workers:  # only the processes this test started
            if _alive(w):
                os.kill(w, signal.SIGKILL)
