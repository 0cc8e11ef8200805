"""Packed stores are written and read streamed: a round trip keeps every byte of the store's rows, and packing a
store needs no more memory than xz's own (about 100 MB at preset 6), whatever the store's size — checked in a
process whose address space is capped below what a whole-file, preset-9 packing takes."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from vbl_robust.store.core import PACKED, ResultStore
from vbl_robust.store.pack import pack_store, restore_store


def _store(path: Path, megabytes: int) -> Path:
    ResultStore(path).close()
    with sqlite3.connect(path) as con:  # ballast beside the store's own tables: incompressible bytes
        con.execute("CREATE TABLE ballast (b BLOB)")
        con.executemany("INSERT INTO ballast VALUES (?)", ((os.urandom(1 << 20),) for _ in range(megabytes)))
    return path


def test_a_packed_store_round_trips_and_a_truncated_one_is_refused(tmp_path):
    src = _store(tmp_path / "run" / "results.sqlite", 2)
    packed = pack_store(ResultStore(src, readonly=True), tmp_path / PACKED)
    assert not (tmp_path / (PACKED + ".part")).exists()
    assert restore_store(packed, tmp_path / "back") is True
    assert restore_store(packed, tmp_path / "back") is False  # an existing store is never replaced
    rows = [sqlite3.connect(p).execute("SELECT b FROM ballast ORDER BY rowid").fetchall()
            for p in (src, tmp_path / "back" / "results.sqlite")]
    assert rows[0] == rows[1]
    with ResultStore.open_existing(packed) as store:  # read in place through a temporary copy
        assert store.count() == 0
    cut = tmp_path / "cut" / PACKED
    cut.parent.mkdir()
    cut.write_bytes(packed.read_bytes()[: packed.stat().st_size // 2])
    with pytest.raises(ValueError, match="not a complete packed store"):
        restore_store(cut, tmp_path / "cut-run")
    assert not (tmp_path / "cut-run" / "results.sqlite").exists()
    assert not (tmp_path / "cut-run" / "results.sqlite.restoring").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc (Linux)")
def test_packing_a_store_stays_in_bounded_memory(tmp_path, full):
    # 48 MB of incompressible ballast under --full (about a minute of xz); 8 MB in make test's small form
    src = _store(tmp_path / "results.sqlite", 48 if full else 8)
    code = textwrap.dedent(f"""
        import resource, sys
        from pathlib import Path
        from vbl_robust.store.core import ResultStore
        from vbl_robust.store.pack import pack_store, restore_store
        peak = int(next(ln for ln in open("/proc/self/status") if ln.startswith("VmSize")).split()[1]) * 1024
        cap = peak + 400 * 2**20  # xz preset 6 needs ~100 MB; preset 9 on the whole file needs ~700 MB more
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        packed = pack_store(ResultStore(Path({str(src)!r}), readonly=True), Path({str(tmp_path / PACKED)!r}))
        print(restore_store(packed, Path({str(tmp_path / "back")!r})))
    """)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0 and res.stdout.strip() == "True", res.stderr[-2000:]
    assert (tmp_path / "back" / "results.sqlite").stat().st_size == src.stat().st_size
