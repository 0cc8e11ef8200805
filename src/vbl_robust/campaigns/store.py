"""The SQLite results store: one row per finished job, provenance per run, resumable and crash-safe.

Layout (one file, ``results.sqlite``):

- ``campaign`` — the one campaign this store holds (spec JSON, detector identity); a run with different
  settings is refused, so a store never mixes incomparable results.
- ``runs`` — one row per invocation: code version, model file SHA-256, dataset identity, full config JSON,
  seed, executor, host, start/finish times, jobs done.
- ``samples`` — id, index, slant distance, envelope, size and a geometry fingerprint of each sample.
- ``jobs`` — one row per finished job, ``key`` UNIQUE: worst value and point, verdict, counts, timings, the
  search trace (JSON) and every evaluated point (JSON, zlib-compressed), or a PnP payload (JSON).

Crash safety: WAL journal, one transaction per finished job (``INSERT OR IGNORE`` on the key). A process
killed at any moment (``kill -9``) loses only the job in progress; committed rows stay and a rerun inserts no
duplicates. Only the driver process writes (Ray workers send their rows back to it).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import sqlite3
import zlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaign (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    name TEXT NOT NULL,
    spec_json TEXT NOT NULL,
    detector_json TEXT NOT NULL,
    created_at TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    run_id INTEGER PRIMARY KEY AUTOINCREMENT,
    started_at TEXT NOT NULL,
    finished_at TEXT,
    status TEXT NOT NULL,
    code_version TEXT,
    model_sha256 TEXT,
    detector_json TEXT,
    dataset_id TEXT,
    dataset_json TEXT,
    config_json TEXT,
    seed INTEGER,
    executor TEXT,
    host TEXT,
    jobs_total INTEGER,
    jobs_skipped INTEGER,
    jobs_done INTEGER DEFAULT 0,
    seconds REAL
);
CREATE TABLE IF NOT EXISTS samples (
    sample_id TEXT PRIMARY KEY,
    sample_index INTEGER,
    slant_distance_m REAL,
    envelope TEXT,
    width INTEGER,
    height INTEGER,
    fingerprint TEXT,
    meta_json TEXT
);
CREATE TABLE IF NOT EXISTS jobs (
    key TEXT NOT NULL UNIQUE,
    run_id INTEGER,
    experiment TEXT, kind TEXT, role TEXT, method TEXT,
    sample_id TEXT, sample_index INTEGER,
    box_label TEXT, box_level REAL, box_json TEXT,
    budget_label TEXT, budget_json TEXT,
    seed INTEGER, options_json TEXT, chain TEXT,
    status TEXT NOT NULL,           -- done | failed | implied
    reason TEXT,                    -- why a job failed / what implied it
    worst_m REAL,                   -- worst error found (m); the penalty for a failed sample
    worst_x_json TEXT,              -- {name: value} of the worst point, real units
    verdict TEXT,                   -- breach | no breach found | certified | failed
    nfev INTEGER, nit INTEGER,
    search_status TEXT, message TEXT,
    search_s REAL,                  -- seconds inside the search (objective calls included)
    job_s REAL,                     -- seconds for the whole job (objective building included)
    upper_bound REAL, bound_estimate REAL, lipschitz_estimate REAL,
    trace_json TEXT,
    points BLOB,                    -- zlib(JSON {"xs": [[...]], "fs": [...]})
    payload_json TEXT,              -- PnP comparison results
    finished_at TEXT
);
CREATE INDEX IF NOT EXISTS jobs_by_sample ON jobs (sample_id);
"""

JOB_COLUMNS = (
    "key", "run_id", "experiment", "kind", "role", "method", "sample_id", "sample_index", "box_label", "box_level",
    "box_json", "budget_label", "budget_json", "seed", "options_json", "chain", "status", "reason", "worst_m",
    "worst_x_json", "verdict", "nfev", "nit", "search_status", "message", "search_s", "job_s", "upper_bound",
    "bound_estimate", "lipschitz_estimate", "trace_json", "points", "payload_json", "finished_at",
)


def now_iso() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


def encode_points(xs: np.ndarray, fs: np.ndarray) -> bytes:
    """Compress evaluated points ``(n, d)`` and values ``(n,)`` (non-finite values stored as null)."""
    f = [None if not math.isfinite(v) else float(v) for v in np.asarray(fs, dtype=np.float64).ravel()]
    return zlib.compress(json.dumps({"xs": np.asarray(xs, dtype=np.float64).tolist(), "fs": f}).encode(), 6)


def decode_points(blob: bytes | None) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`encode_points` (null values come back as NaN); empty arrays for None."""
    if not blob:
        return np.zeros((0, 0)), np.zeros(0)
    d = json.loads(zlib.decompress(blob))
    fs = np.array([math.nan if v is None else v for v in d["fs"]], dtype=np.float64)
    xs = np.asarray(d["xs"], dtype=np.float64).reshape(len(fs), -1)
    return xs, fs


class ResultStore:
    """A campaign's results in one SQLite file (see the module docstring for the layout).

    >>> import tempfile, pathlib
    >>> store = ResultStore(pathlib.Path(tempfile.mkdtemp()) / "results.sqlite")
    >>> store.count()
    0
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # isolation_level=None: we open transactions ourselves (BEGIN IMMEDIATE … COMMIT).
        self._con = sqlite3.connect(str(self.path), isolation_level=None, timeout=30.0)
        self._con.execute("PRAGMA journal_mode=WAL")
        self._con.execute("PRAGMA synchronous=NORMAL")  # durable against process kills (not power loss)
        self._con.executescript(_SCHEMA)

    @classmethod
    def open_existing(cls, path: str | Path) -> ResultStore:
        """Open a store that must exist (a run directory or the ``.sqlite`` file itself)."""
        p = Path(path)
        if p.is_dir():
            p = p / "results.sqlite"
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no results store (run `vbl-robust audit` or `reproduce` with --out first)")
        return cls(p)

    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- campaign and runs ----------------------------------------------------------------------------------
    def campaign(self) -> dict[str, Any] | None:
        """The stored campaign ``{"name", "spec", "detector", "created_at"}`` or None for a new store."""
        row = self._con.execute("SELECT name, spec_json, detector_json, created_at FROM campaign WHERE id = 1").fetchone()
        if row is None:
            return None
        return {"name": row[0], "spec": json.loads(row[1]), "detector": json.loads(row[2]), "created_at": row[3]}

    def bind_campaign(self, name: str, spec: Mapping[str, Any], detector: Mapping[str, Any]) -> None:
        """Record the campaign on first use; refuse (``ValueError``) a different one later."""
        have = self.campaign()
        spec_j = json.dumps(spec, sort_keys=True)
        det_j = json.dumps(detector, sort_keys=True)
        if have is None:
            with self._tx():
                self._con.execute("INSERT INTO campaign VALUES (1, ?, ?, ?, ?)", (name, spec_j, det_j, now_iso()))
            return
        if json.dumps(have["spec"], sort_keys=True) != spec_j:
            diff = _first_difference(have["spec"], json.loads(spec_j))
            raise ValueError(
                f"{self.path}: holds campaign {have['name']!r} with other settings ({diff}); "
                "rerun with the same options to resume, or use another --out"
            )
        if have["detector"].get("sha256") != detector.get("sha256") or have["detector"].get("kind") != detector.get("kind"):
            raise ValueError(
                f"{self.path}: holds results of detector {have['detector'].get('name')!r} "
                f"(sha256 {str(have['detector'].get('sha256'))[:12]}…), not of {detector.get('name')!r}; use another --out"
            )

    def begin_run(self, provenance: Mapping[str, Any]) -> int:
        """Insert a run row (status "running") and return its id."""
        cols = ("started_at", "status", "code_version", "model_sha256", "detector_json", "dataset_id", "dataset_json",
                "config_json", "seed", "executor", "host", "jobs_total", "jobs_skipped")
        p = dict(provenance)
        vals = (now_iso(), "running", p.get("code_version"), p.get("model_sha256"), _dumps(p.get("detector")),
                p.get("dataset_id"), _dumps(p.get("dataset")), _dumps(p.get("config")), p.get("seed"),
                p.get("executor"), p.get("host"), p.get("jobs_total"), p.get("jobs_skipped"))
        with self._tx():
            cur = self._con.execute(f"INSERT INTO runs ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})", vals)
        return int(cur.lastrowid)

    def end_run(self, run_id: int, status: str, jobs_done: int, seconds: float) -> None:
        with self._tx():
            self._con.execute("UPDATE runs SET finished_at = ?, status = ?, jobs_done = ?, seconds = ? WHERE run_id = ?",
                              (now_iso(), status, jobs_done, seconds, run_id))

    def runs(self) -> list[dict[str, Any]]:
        cur = self._con.execute("SELECT * FROM runs ORDER BY run_id")
        names = [c[0] for c in cur.description]
        out = []
        for r in cur.fetchall():
            d = dict(zip(names, r, strict=True))
            for k in ("detector_json", "dataset_json", "config_json"):
                d[k.removesuffix("_json")] = _loads(d.pop(k))
            out.append(d)
        return out

    # -- samples ------------------------------------------------------------------------------------------
    def add_samples(self, rows: Iterable[Mapping[str, Any]]) -> None:
        cols = ("sample_id", "sample_index", "slant_distance_m", "envelope", "width", "height", "fingerprint", "meta_json")
        with self._tx():
            self._con.executemany(
                f"INSERT OR IGNORE INTO samples ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
                [tuple(r.get(c) for c in cols) for r in rows],
            )

    def samples(self) -> dict[str, dict[str, Any]]:
        cur = self._con.execute("SELECT * FROM samples ORDER BY sample_index")
        names = [c[0] for c in cur.description]
        return {r[0]: dict(zip(names, r, strict=True)) for r in cur.fetchall()}

    # -- jobs ---------------------------------------------------------------------------------------------
    def done_keys(self) -> set[str]:
        return {r[0] for r in self._con.execute("SELECT key FROM jobs")}

    def count(self) -> int:
        return int(self._con.execute("SELECT COUNT(*) FROM jobs").fetchone()[0])

    def commit(self, rows: Sequence[Mapping[str, Any]]) -> int:
        """Insert the rows of finished jobs in one transaction; returns how many were new (duplicates ignored)."""
        if not rows:
            return 0
        sql = f"INSERT OR IGNORE INTO jobs ({', '.join(JOB_COLUMNS)}) VALUES ({', '.join('?' * len(JOB_COLUMNS))})"
        with self._tx():
            before = self._con.total_changes
            self._con.executemany(sql, [tuple(r.get(c) for c in JOB_COLUMNS) for r in rows])
            return self._con.total_changes - before

    def jobs(self, *, kind: str | None = None, role: str | None = None, with_points: bool = False,
             with_trace: bool = True) -> list[dict[str, Any]]:
        """Job rows as dicts with JSON decoded (``box``, ``budget``, ``worst_x``, ``trace``, ``payload``,
        ``options``); ``xs``/``fs`` arrays when ``with_points``. Ordered by sample index, then insertion."""
        where, args = [], []
        if kind is not None:
            where.append("kind = ?")
            args.append(kind)
        if role is not None:
            where.append("role = ?")
            args.append(role)
        cols = [c for c in JOB_COLUMNS if (with_points or c != "points") and (with_trace or c != "trace_json")]
        sql = f"SELECT {', '.join(cols)} FROM jobs" + (f" WHERE {' AND '.join(where)}" if where else "")
        sql += " ORDER BY sample_index, rowid"
        out = []
        for r in self._con.execute(sql, args):
            d = dict(zip(cols, r, strict=True))
            for k in ("box_json", "budget_json", "options_json", "worst_x_json", "trace_json", "payload_json"):
                if k in d:
                    d[k.removesuffix("_json")] = _loads(d.pop(k))
            if with_points:
                d["xs"], d["fs"] = decode_points(d.pop("points"))
            out.append(d)
        return out

    # -- helpers ------------------------------------------------------------------------------------------
    def _tx(self) -> _Transaction:
        return _Transaction(self._con)


class _Transaction:
    """``BEGIN IMMEDIATE`` … ``COMMIT`` (``ROLLBACK`` on error)."""

    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def __enter__(self) -> None:
        self.con.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type: object, *_: object) -> None:
        self.con.execute("ROLLBACK" if exc_type is not None else "COMMIT")


def _dumps(v: Any) -> str | None:
    return None if v is None else json.dumps(v, sort_keys=True, default=str)


def _loads(v: str | None) -> Any:
    return None if v is None else json.loads(v)


def _first_difference(a: Any, b: Any, path: str = "") -> str:
    """Human-readable location of the first difference between two JSON values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{path}[{i}]")
    return f"{path or 'spec'}: stored {json.dumps(a)[:80]} vs now {json.dumps(b)[:80]}"
