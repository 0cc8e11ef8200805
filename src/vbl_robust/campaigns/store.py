"""The SQLite results store: one :class:`JobRow` per finished job, provenance per run, resumable and crash-safe.

Layout (one file, ``results.sqlite``; schema version :data:`SCHEMA_VERSION` in ``PRAGMA user_version``):

- ``campaign`` — the one campaign this store holds (spec JSON, detector identity); once a job row is stored, a
  run with different settings or another detector is refused, so a store never mixes incomparable results.
- ``runs`` — one row per invocation: code version, model file SHA-256, dataset identity, full config JSON,
  seed, executor, host, start/finish times, jobs done.
- ``samples`` — id, index, slant distance, envelope, size and a geometry fingerprint of each sample.
- ``contents`` — for a sample read from an image file: the file's SHA-256 (with its size and mtime, so it is
  recomputed only when they change): a rerun on changed pixels is refused (:meth:`ResultStore.check_contents`)
  instead of reusing results computed on the old ones.
- ``jobs`` — one row per finished job (:class:`JobRow`), ``key`` UNIQUE: worst value and point, verdict,
  counts (failed evaluations per reason included), timings, the search trace (JSON) and every evaluated point
  with its failure reason and completion time (JSON, zlib-compressed), or a PnP payload (JSON).

Crash safety: WAL journal, one transaction per finished job (``INSERT OR IGNORE`` on the key). A process
killed at any moment (``kill -9``) loses only the job in progress; committed rows stay and a rerun inserts no
duplicates. Only the driver process writes (Ray workers send their rows back to it), and one driver at a time:
a campaign holds :class:`WriterLock` on its store for its whole run (an OS file lock, released when the process
ends, however it ends), so two runs never mix in one store.

Schema versions: 0/1 = before failures were recorded (no ``n_failed``, ``failures_json``, ``worst_reason``
columns: they are added on open, old rows read them as unknown); 2 = failures recorded; 3 = now: every evaluated
point carries its completion time on the search's clock (``ts`` in the points blob, so no column is added; rows
written before read ``Points.times`` as None, and no time budget can be read off them); 4 = now: a main search
job stores the corners its detector predicted at the worst point (``worst_corners_json``, added on open; rows
written before read ``JobRow.worst_corners`` as None). A store written by a newer version is refused with a
one-line error.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import math
import sqlite3
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from ..constants import MAX_BLOB_BYTES, Verdict
from ..search.result import TraceRow
from .spec import BoxSpec, Budget

#: Version of the layout below (``PRAGMA user_version``).
SCHEMA_VERSION = 4

_SCHEMA_TEMPLATE = """
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
CREATE TABLE IF NOT EXISTS contents (
    sample_id TEXT PRIMARY KEY,     -- a sample read from an image file: what its pixels were
    path TEXT, size INTEGER, mtime_ns INTEGER,
    sha256 TEXT                     -- of the file's bytes; recomputed only when size or mtime changed
);
{jobs}
CREATE INDEX IF NOT EXISTS jobs_by_sample ON jobs (sample_id);
"""


def _same(v: Any) -> Any:
    return v


def _json(v: Any) -> str | None:
    return None if v is None else json.dumps(v)


def _loads(v: str | None) -> Any:
    return None if v is None else json.loads(v)


#: Four predicted runway corners ``((u, v), …)`` in the sample's pixels, keypoint order TR, TL, BL, BR.
Corners = tuple[tuple[float, float], ...]


def _dump_corners(c: Corners | None) -> str | None:
    return None if c is None else json.dumps([[float(u), float(v)] for u, v in c])


def _load_corners(v: str | None) -> Corners | None:
    d = _loads(v)
    return None if d is None else tuple((float(u), float(w)) for u, w in d)


@dataclass(frozen=True)
class _Column:
    """One column of the jobs table: its declaration, the :class:`JobRow` field it holds and how the value goes in
    (``dump``) and comes out (``load``; None: a column derived on write only, e.g. ``box_label`` for queries)."""

    name: str
    decl: str
    field: str
    dump: Any = _same
    load: Any = _same
    comment: str = ""
    since: int = 0  # the schema version that added it (added to older stores on open)


#: The jobs table, in column order: the one place a job field is declared, written and read.
_JOB_TABLE: tuple[_Column, ...] = (
    _Column("key", "TEXT NOT NULL UNIQUE", "key"),
    _Column("run_id", "INTEGER", "run_id"),
    *(_Column(n, "TEXT", n) for n in ("experiment", "kind", "role", "method", "sample_id")),
    _Column("sample_index", "INTEGER", "sample_index"),
    _Column("box_label", "TEXT", "box_label", load=None),
    _Column("box_level", "REAL", "box_level", load=None),
    _Column("box_json", "TEXT", "box", lambda b: None if b is None else json.dumps(b.to_dict()),
            lambda v: None if v is None else BoxSpec.from_dict(json.loads(v))),
    _Column("budget_label", "TEXT", "budget_label", load=None),
    _Column("budget_json", "TEXT", "budget", lambda b: None if b is None else json.dumps(b.to_dict()),
            lambda v: None if v is None else Budget.from_dict(json.loads(v))),
    _Column("seed", "INTEGER", "seed"),
    _Column("options_json", "TEXT", "options", lambda o: json.dumps(dict(o)), lambda v: _loads(v) or {}),
    _Column("chain", "TEXT", "chain"),
    _Column("status", "TEXT NOT NULL", "status", lambda st: st.value, comment="done | failed | implied"),
    _Column("reason", "TEXT", "reason", comment="why a job failed / what implied it"),
    _Column("worst_m", "REAL", "worst_m", comment="worst error found (m); the penalty for a failed sample"),
    _Column("worst_x_json", "TEXT", "worst_x", lambda x: _json(None if x is None else dict(x)), _loads,
            comment="{name: value} of the worst point, real units"),
    _Column("verdict", "TEXT", "verdict", lambda v: None if v is None else v.value,
            comment="breach | no breach found | certified | failed"),
    _Column("nfev", "INTEGER", "nfev", load=lambda v: v or 0),
    _Column("nit", "INTEGER", "nit", load=lambda v: v or 0),
    _Column("search_status", "TEXT", "search_status"),
    _Column("message", "TEXT", "message"),
    _Column("search_s", "REAL", "search_s", comment="seconds inside the search (objective calls included)"),
    _Column("job_s", "REAL", "job_s", comment="seconds for the whole job (objective building included)"),
    *(_Column(n, "REAL", n) for n in ("upper_bound", "bound_estimate", "lipschitz_estimate")),
    _Column("trace_json", "TEXT", "trace", lambda tr: json.dumps([t.to_dict() for t in tr]) if tr else None,
            lambda v: tuple(TraceRow.from_dict(t) for t in _loads(v) or ())),
    _Column("points", "BLOB", "points", lambda pt: None if pt is None else pt.to_blob(),
            lambda v: Points.from_blob(v) if v else None,
            comment='zlib(JSON {"xs": [[...]], "fs": [...], "reasons": [...], "ts": [...]})'),
    _Column("payload_json", "TEXT", "payload", _json, _loads,
            comment="PnP comparison results, details of the worst point"),
    _Column("finished_at", "TEXT", "finished_at"),
    _Column("n_failed", "INTEGER", "n_failed", comment="failed evaluations (schema 2)", since=2),
    _Column("failures_json", "TEXT", "failures", lambda f: json.dumps(dict(f)) if f else None,
            lambda v: _loads(v) or {}, comment="{reason: count} of the failed evaluations (schema 2)", since=2),
    _Column("worst_reason", "TEXT", "worst_reason", since=2,
            comment='failure reason at the worst point, "" = a successful evaluation (schema 2)'),
    _Column("worst_corners_json", "TEXT", "worst_corners", _dump_corners, _load_corners, since=4,
            comment="[[u, v] x 4] corners predicted at the worst point, sample's pixels (schema 4)"),
)


def _jobs_ddl() -> str:
    lines = [f"    {c.name} {c.decl}{',' if i < len(_JOB_TABLE) - 1 else ''}{f'  -- {c.comment}' if c.comment else ''}"
             for i, c in enumerate(_JOB_TABLE)]
    return "CREATE TABLE IF NOT EXISTS jobs (\n" + "\n".join(lines) + "\n);"


_SCHEMA = _SCHEMA_TEMPLATE.format(jobs=_jobs_ddl())

#: Columns added after the first layout (schema 2: failures; 4: predicted corners), added to an older store on open.
_ADDED_COLUMNS = {c.name: c.decl for c in _JOB_TABLE if c.since}

JOB_COLUMNS = tuple(c.name for c in _JOB_TABLE)

#: Keys of a campaign spec that only change how results are shown (the report's figures): they never make a
#: store refuse a run, and the newer value is recorded.
PRESENTATION_KEYS = ("figures",)


class WriterLock:
    """The one-writer lock of a store: an exclusive ``flock`` on ``<store>.lock`` (which holds the writer's PID) and
    on the store file itself, held from :meth:`acquire` to :meth:`release` or the end of the process. A second
    writer gets a ``ValueError`` naming the PID that holds it, or waits for it with ``wait=True``. The lock on the
    store file keeps a second writer out even when ``<store>.lock`` is deleted during a run (a new lock file would
    be a new, free lock); ``flock`` does not interfere with SQLite's own (POSIX) locks, so readers are unaffected."""

    def __init__(self, store_path: str | Path):
        self.store = Path(store_path)
        self.path = Path(f"{store_path}.lock")
        self._fds: list[int] = []

    def acquire(self, wait: bool = False) -> WriterLock:
        import fcntl
        import os

        fds = []
        try:
            for target in (self.path, self.store):
                fd = os.open(target, os.O_RDWR | os.O_CREAT, 0o644)
                fds.append(fd)
                fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            try:
                holder = self.path.read_text().strip() or "another process"
            except OSError:
                holder = "another process"
            for fd in fds:
                os.close(fd)
            raise ValueError(f"{self.path.parent}: in use by PID {holder} (another run is writing this store); wait "
                             "for it to end or write to another --out") from None
        try:
            os.ftruncate(fds[0], 0)
            os.pwrite(fds[0], str(os.getpid()).encode(), 0)
        except OSError as exc:  # e.g. a full disk: named after the lock file
            for fd in fds:
                os.close(fd)
            raise OSError(exc.errno, exc.strerror, str(self.path)) from None
        self._fds = fds
        return self

    def release(self) -> None:
        import fcntl
        import os

        for fd in self._fds:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        self._fds = []

    def __enter__(self) -> WriterLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def now_iso() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


class JobStatus(StrEnum):
    """How a job ended: searched (``DONE``), could not run (``FAILED``), or implied by a breach in a chain."""

    DONE = "done"
    FAILED = "failed"
    IMPLIED = "implied"


@dataclass(frozen=True, eq=False)
class Points:
    """Every point one search evaluated, in evaluation order.

    Attributes:
        xs: ``(n, d)`` points, real units (columns ordered as the box's names).
        fs: ``(n,)`` values, metres (NaN where the value was not finite).
        reasons: ``n`` failure reasons, ``""`` = success (all ``""`` when not given).
        times: ``(n,)`` completion time of each evaluation, seconds on the search's clock (None: not recorded,
            rows stored before schema 3).
    """

    xs: np.ndarray
    fs: np.ndarray
    reasons: tuple[str, ...] = ()
    times: np.ndarray | None = None

    def __post_init__(self) -> None:
        fs = np.asarray(self.fs, dtype=np.float64).reshape(-1)
        xs = np.asarray(self.xs, dtype=np.float64)
        xs = xs.reshape(len(fs), -1) if len(fs) else xs.reshape(0, xs.shape[-1] if xs.ndim == 2 else 0)
        reasons = tuple(self.reasons) or ("",) * len(fs)
        if len(reasons) != len(fs):
            raise ValueError(f"Points: {len(reasons)} reasons for {len(fs)} values")
        object.__setattr__(self, "xs", xs)
        object.__setattr__(self, "fs", fs)
        object.__setattr__(self, "reasons", reasons)
        if self.times is not None:
            ts = np.asarray(self.times, dtype=np.float64).reshape(-1)
            if len(ts) != len(fs):
                raise ValueError(f"Points: {len(ts)} times for {len(fs)} values")
            object.__setattr__(self, "times", ts)

    def __len__(self) -> int:
        return len(self.fs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Points):
            return NotImplemented
        return (self.xs.shape == other.xs.shape and np.array_equal(self.xs, other.xs)
                and np.array_equal(self.fs, other.fs, equal_nan=True) and self.reasons == other.reasons
                and (self.times is None) == (other.times is None)
                and (self.times is None or np.array_equal(self.times, other.times, equal_nan=True)))

    __hash__ = None  # type: ignore[assignment]

    def to_blob(self) -> bytes:
        """zlib-compressed JSON; non-finite values as null, reasons only when some point failed, times when known."""
        d: dict[str, Any] = {"xs": self.xs.tolist(), "fs": [v if math.isfinite(v) else None for v in self.fs.tolist()],
                             "d": self.xs.shape[1]}
        if any(self.reasons):
            d["reasons"] = list(self.reasons)
        if self.times is not None:
            d["ts"] = [v if math.isfinite(v) else None for v in self.times.tolist()]
        return zlib.compress(json.dumps(d).encode(), 6)

    @classmethod
    def from_blob(cls, blob: bytes) -> Points:
        """Inverse of :meth:`to_blob` (null values come back as NaN, missing reasons as ``""``, missing times as
        None)."""
        d = json.loads(_inflate(blob))
        fs = np.array([math.nan if v is None else v for v in d["fs"]], dtype=np.float64)
        xs = np.asarray(d["xs"], dtype=np.float64).reshape(len(fs), d.get("d", -1 if len(fs) else 0))
        ts = d.get("ts")
        times = None if ts is None else np.array([math.nan if v is None else v for v in ts], dtype=np.float64)
        return cls(xs, fs, tuple(d.get("reasons", ())), times)


def encode_points(xs: np.ndarray, fs: np.ndarray, reasons: Sequence[str] = ()) -> bytes:
    """Compress evaluated points ``(n, d)``, values ``(n,)`` and reasons (see :meth:`Points.to_blob`)."""
    return Points(xs, fs, tuple(reasons)).to_blob()


def _inflate(blob: bytes) -> bytes:
    """``zlib`` decompression that refuses to grow past :data:`~vbl_robust.constants.MAX_BLOB_BYTES` (a crafted
    store must not exhaust memory): ``ValueError`` naming the bound."""
    d = zlib.decompressobj()
    out = d.decompress(blob, MAX_BLOB_BYTES)
    if d.unconsumed_tail:
        raise ValueError(f"a stored blob decompresses to more than {MAX_BLOB_BYTES} bytes (a damaged or crafted store)")
    return out + d.flush()


def decode_points(blob: bytes | None) -> tuple[np.ndarray, np.ndarray]:
    """``(xs, fs)`` of :func:`encode_points` (null values come back as NaN); empty arrays for None."""
    if not blob:
        return np.zeros((0, 0)), np.zeros(0)
    p = Points.from_blob(blob)
    return p.xs, p.fs


@dataclass(frozen=True)
class JobRow:
    """One finished job as the store holds it (what a worker produces and ``ResultStore.jobs`` returns).

    Identity (from the :class:`~vbl_robust.campaigns.spec.Job`): ``key``, ``experiment``, ``kind`` ("search" |
    "pnp"), ``role`` ("main" | "reference" | "landscape"), ``method``, ``sample_id``, ``sample_index``, ``box``,
    ``budget``, ``seed``, ``options``, ``chain``; ``run_id`` = the run that computed it.

    Outcome: ``status``; ``reason`` (why a job failed / what implied it); ``worst_m`` = worst error found,
    metres (the penalty for a failed job); ``worst_x`` = ``{name: value}`` of the worst point, real units;
    ``verdict`` (None for a PnP job); ``nfev``/``nit`` = evaluations / iterations; ``n_failed`` = failed
    evaluations and ``failures`` = their counts per reason (None / ``{}`` in rows stored before failures were
    recorded); ``worst_reason`` = failure reason at the worst point (``""`` = a successful evaluation, None
    unknown); ``worst_corners`` = the four corners the detector's selected candidate gave at the worst point, in the
    sample's pixels of the perturbed view (TR, TL, BL, BR; main search jobs from schema 4 on, None when no candidate
    was found, for other jobs and in older rows; its confidence is ``payload["worst"]["conf"]``);
    ``search_status``/``message`` = why the search stopped; ``search_s``/``job_s`` = seconds in the
    search / in the whole job; ``upper_bound`` (sound, metres; 1e300 for "unbounded"), ``bound_estimate``,
    ``lipschitz_estimate``; ``trace`` = the search's iterations (empty unless asked for); ``points`` = every
    evaluated point (None unless asked for); ``payload`` = PnP comparison or details of the worst point;
    ``finished_at`` (ISO time, UTC). ``read_from`` is set only on rows *derived* from a stored run at a smaller
    budget (:func:`vbl_robust.campaigns.metrics.read_off_rows`; never stored): the budget label of that run.

    Floats are finite or None (SQLite stores NaN as NULL).
    """

    key: str
    experiment: str
    kind: str
    role: str
    method: str
    sample_id: str
    sample_index: int
    status: JobStatus
    run_id: int | None = None
    box: BoxSpec | None = None
    budget: Budget | None = None
    seed: int | None = None
    options: Mapping[str, Any] = field(default_factory=dict)
    chain: str | None = None
    reason: str | None = None
    worst_m: float | None = None
    worst_x: Mapping[str, float] | None = None
    verdict: Verdict | None = None
    nfev: int = 0
    nit: int = 0
    n_failed: int | None = None
    failures: Mapping[str, int] = field(default_factory=dict)
    worst_reason: str | None = None
    worst_corners: Corners | None = None
    search_status: str | None = None
    message: str | None = None
    search_s: float | None = None
    job_s: float | None = None
    upper_bound: float | None = None
    bound_estimate: float | None = None
    lipschitz_estimate: float | None = None
    trace: tuple[TraceRow, ...] = ()
    points: Points | None = None
    payload: Mapping[str, Any] | None = None
    finished_at: str | None = None
    read_from: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", JobStatus(self.status))
        if self.verdict is not None:
            object.__setattr__(self, "verdict", Verdict(self.verdict))
        object.__setattr__(self, "trace", tuple(self.trace))

    @property
    def box_label(self) -> str | None:
        return None if self.box is None else self.box.label

    @property
    def box_level(self) -> float | None:
        return None if self.box is None else self.box.level

    @property
    def budget_label(self) -> str | None:
        return None if self.budget is None else self.budget.label

    def replace(self, **changes: Any) -> JobRow:
        """A copy with ``changes`` (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


def _to_columns(r: JobRow) -> tuple[Any, ...]:
    return tuple(c.dump(getattr(r, c.field)) for c in _JOB_TABLE)


def _from_columns(d: Mapping[str, Any]) -> JobRow:
    """A row from the columns read (``points`` / ``trace_json`` may be left out: None / empty)."""
    return JobRow(**{c.field: c.load(d[c.name]) for c in _JOB_TABLE if c.load is not None and c.name in d})


class ResultStore:
    """A campaign's results in one SQLite file (see the module docstring for the layout).

    >>> import tempfile, pathlib
    >>> store = ResultStore(pathlib.Path(tempfile.mkdtemp()) / "results.sqlite")
    >>> store.count()
    0
    """

    def __init__(self, path: str | Path, *, readonly: bool = False):
        self.path = Path(path)
        self.readonly = readonly
        try:
            if readonly:
                self._con = self._open_readonly()
                return
            self.path.parent.mkdir(parents=True, exist_ok=True)
            # isolation_level=None: we open transactions ourselves (BEGIN IMMEDIATE … COMMIT).
            self._con = sqlite3.connect(str(self.path), isolation_level=None, timeout=30.0)
            try:
                self._con.execute("PRAGMA journal_mode=WAL")
                self._con.execute("PRAGMA synchronous=NORMAL")  # durable against process kills (not power loss)
                self._migrate()
            except BaseException:
                self._con.close()
                raise
        except sqlite3.DatabaseError as exc:  # truncated, or not SQLite at all: one line, not a traceback
            raise ValueError(f"{self.path}: not a readable vbl-robust results store ({exc})") from None

    def _open_readonly(self) -> sqlite3.Connection:
        """A connection that writes nothing. Without a write-ahead log beside the file (no writer, nothing left to
        replay) the file is read as it stands (``immutable``: no ``-shm``/``-wal`` file is made, so it works in a
        read-only directory; a writer that starts meanwhile writes its log, not this file, until a checkpoint);
        with one, SQLite's read-only mode reads the log too (and falls back to the file alone where the log's
        shared memory cannot be opened). A store of an older layout is copied into memory and updated there."""
        uri = self.path.resolve().as_uri()
        con = None
        if Path(f"{self.path}-wal").exists():
            con = sqlite3.connect(f"{uri}?mode=ro", uri=True, isolation_level=None, timeout=30.0)
            try:
                version = int(con.execute("PRAGMA user_version").fetchone()[0])
            except sqlite3.OperationalError:
                con.close()
                con = None
        if con is None:
            con = sqlite3.connect(f"{uri}?mode=ro&immutable=1", uri=True, isolation_level=None)
            version = int(con.execute("PRAGMA user_version").fetchone()[0])
        if version < SCHEMA_VERSION:
            mem = sqlite3.connect(":memory:", isolation_level=None)
            con.backup(mem)
            con.close()
            self._con = con = mem
            self._migrate()
        elif version > SCHEMA_VERSION:
            con.close()
            raise ValueError(f"{self.path}: results store schema version {version} is newer than this vbl-robust's "
                             f"({SCHEMA_VERSION}); upgrade vbl-robust to read it")
        con.execute("PRAGMA query_only = ON")
        return con

    @classmethod
    def open_existing(cls, path: str | Path, *, readonly: bool = True) -> ResultStore:
        """Open a store that must exist (a run directory or the ``.sqlite`` file itself) — read-only unless told
        otherwise: reading a run (report, zones, tables, bundles) never writes it, and works where it cannot."""
        p = Path(path)
        if p.is_dir():
            p = p / "results.sqlite"
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no results store (run `vbl-robust audit` or `reproduce` with --out first)")
        return cls(p, readonly=readonly)

    def _migrate(self) -> None:
        """Create the tables of a new store; bring an older one to :data:`SCHEMA_VERSION` (adds columns)."""
        version = int(self._con.execute("PRAGMA user_version").fetchone()[0])
        if version > SCHEMA_VERSION:
            self._con.close()
            raise ValueError(f"{self.path}: results store schema version {version} is newer than this vbl-robust's "
                             f"({SCHEMA_VERSION}); upgrade vbl-robust to read it")
        self._con.executescript(_SCHEMA)
        if version == SCHEMA_VERSION:
            return
        have = {r[1] for r in self._con.execute("PRAGMA table_info(jobs)")}
        with self._tx():
            for name, kind in _ADDED_COLUMNS.items():
                if name not in have:
                    self._con.execute(f"ALTER TABLE jobs ADD COLUMN {name} {kind}")
            self._con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

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
        """Bind the store to a campaign and detector, or check that it holds this one.

        A store is bound by what was computed in it: while it holds no job row (a new store, or a run that
        failed before its first job, e.g. on a refused model file), the campaign and detector are recorded
        anew and samples recorded by that run are forgotten. Once it holds a job row, another campaign (spec,
        :data:`PRESENTATION_KEYS` aside) or another detector (kind, model SHA-256 and options such as the design or
        the oracle's noise: :func:`_detector_identity`) is refused (``ValueError``).
        """
        have = self.campaign()
        spec_j = json.dumps(spec, sort_keys=True)
        det_j = json.dumps(detector, sort_keys=True)
        bound = have is not None and self.count() > 0
        if bound:
            self._check_same(have, dict(spec), detector)
        with self._tx():
            if not bound:
                self._con.execute("DELETE FROM samples")
            created = have["created_at"] if bound else now_iso()
            self._con.execute("INSERT OR REPLACE INTO campaign VALUES (1, ?, ?, ?, ?)", (name, spec_j, det_j, created))

    def _check_same(self, have: Mapping[str, Any], spec: dict[str, Any], detector: Mapping[str, Any], *,
                    hint: str = "rerun with the same options to resume, or use another --out") -> None:
        def shown(d: Mapping[str, Any]) -> str:
            return json.dumps({k: v for k, v in d.items() if k not in PRESENTATION_KEYS}, sort_keys=True)

        if shown(have["spec"]) != shown(spec):
            diff = _first_difference(have["spec"], spec)
            raise ValueError(f"{self.path}: holds campaign {have['name']!r} with other settings ({diff}); {hint}")
        mine, theirs = _detector_identity(have["detector"]), _detector_identity(detector)
        if mine != theirs:
            diff = _first_difference(mine, theirs)
            raise ValueError(
                f"{self.path}: holds results of detector {have['detector'].get('name')!r} "
                f"(sha256 {str(have['detector'].get('sha256'))[:12]}…), not of {detector.get('name')!r} ({diff}); "
                + ("use another --out" if hint.startswith("rerun") else hint))

    def begin_run(self, provenance: Mapping[str, Any]) -> int:
        """Insert a run row (status "running") and return its id. Called under the store's writer lock
        (:func:`~vbl_robust.campaigns.runner.run_campaign`), so an earlier run still marked "running" has ended
        without recording it (SIGKILL, a machine's or session's end): it is closed first as "killed", finished at
        its last stored job, its seconds up to that job (:meth:`close_killed_runs`)."""
        self.close_killed_runs()
        cols = ("started_at", "status", "code_version", "model_sha256", "detector_json", "dataset_id", "dataset_json",
                "config_json", "seed", "executor", "host", "jobs_total", "jobs_skipped")
        p = dict(provenance)
        vals = (now_iso(), "running", p.get("code_version"), p.get("model_sha256"), _dumps(p.get("detector")),
                p.get("dataset_id"), _dumps(p.get("dataset")), _dumps(p.get("config")), p.get("seed"),
                p.get("executor"), p.get("host"), p.get("jobs_total"), p.get("jobs_skipped"))
        with self._tx():
            cur = self._con.execute(f"INSERT INTO runs ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})", vals)
        return int(cur.lastrowid)

    def close_killed_runs(self) -> int:
        """Mark every run still "running" as "killed": finished at its last stored job (its start if none), its
        jobs done and its seconds up to then. Only a writer holding the store's lock may call it (a run in progress
        elsewhere would be closed too); returns how many runs it closed."""
        last = "(SELECT max(j.finished_at) FROM jobs j WHERE j.run_id = runs.run_id)"
        with self._tx():
            cur = self._con.execute(
                f"UPDATE runs SET status = 'killed', finished_at = coalesce({last}, started_at), "
                "jobs_done = (SELECT count(*) FROM jobs j WHERE j.run_id = runs.run_id), "
                f"seconds = max(0.0, 86400.0 * (julianday(coalesce({last}, started_at)) - julianday(started_at))) "
                "WHERE status = 'running'")
        return cur.rowcount

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
        with self._tx():
            self._insert_samples(rows)

    def _insert_samples(self, rows: Iterable[Mapping[str, Any]]) -> None:
        """The samples' rows, inside the caller's transaction."""
        cols = ("sample_id", "sample_index", "slant_distance_m", "envelope", "width", "height", "fingerprint", "meta_json")
        self._con.executemany(
            f"INSERT OR IGNORE INTO samples ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
            [tuple(r.get(c) for c in cols) for r in rows],
        )

    def samples(self) -> dict[str, dict[str, Any]]:
        cur = self._con.execute("SELECT * FROM samples ORDER BY sample_index")
        names = [c[0] for c in cur.description]
        return {r[0]: dict(zip(names, r, strict=True)) for r in cur.fetchall()}

    def check_contents(self, samples: Iterable[Any]) -> None:
        """Record the image-file digest of each sample (each frame of a sequence) read from a file (``image_path``), and refuse
        (``ValueError`` naming them) samples whose file's bytes differ from those their stored jobs were computed
        on. Every file is hashed on every run: a size and mtime that did not change prove nothing (``cp -p``,
        ``tar x`` and ``rsync -a`` keep them for other bytes); samples rendered in memory have no file (their pixels
        follow from their geometry and the generator, both in the job keys and the provenance)."""
        from ..digest import file_sha256

        stored = {r[0]: r[1:] for r in self._con.execute("SELECT sample_id, size, mtime_ns, sha256 FROM contents")}
        with_jobs = {r[0] for r in self._con.execute("SELECT DISTINCT sample_id FROM jobs")}
        changed, rows = [], []
        for owner in samples:  # a sequence campaign's sample is an approach sequence: each frame has its file
            for s in getattr(owner, "samples", None) or (owner,):
                path = getattr(s, "image_path", None)
                if path is None or not Path(path).is_file():
                    continue  # rendered in memory, or missing (the job records that failure)
                st = Path(path).stat()
                old = stored.get(s.id)
                digest = file_sha256(path)
                if old is not None and old[2] != digest and owner.id in with_jobs:
                    changed.append(f"{s.id} ({path})")
                    continue
                rows.append((s.id, str(path), st.st_size, st.st_mtime_ns, digest))
        if changed:
            raise ValueError(f"{self.path}: the pixels of {len(changed)} sample(s) changed since their results were "
                             f"stored: {', '.join(changed[:5])}{' …' if len(changed) > 5 else ''}; run them into "
                             "another --out (the stored results describe the old images)")
        with self._tx():
            self._con.executemany("INSERT OR REPLACE INTO contents (sample_id, path, size, mtime_ns, sha256) "
                                  "VALUES (?, ?, ?, ?, ?)", rows)

    # -- jobs ---------------------------------------------------------------------------------------------
    def done_keys(self) -> set[str]:
        return {r[0] for r in self._con.execute("SELECT key FROM jobs")}

    def count(self) -> int:
        return int(self._con.execute("SELECT COUNT(*) FROM jobs").fetchone()[0])

    def forget_failed(self) -> int:
        """Delete the rows of failed jobs (status "failed": the pipeline could not run them), so that a rerun runs
        them again; returns how many were deleted."""
        with self._tx():
            before = self._con.total_changes
            self._con.execute("DELETE FROM jobs WHERE status = ?", (JobStatus.FAILED.value,))
            return self._con.total_changes - before

    def commit(self, rows: Sequence[JobRow]) -> int:
        """Insert the rows of finished jobs in one transaction; returns how many were new (duplicates ignored)."""
        if not rows:
            return 0
        sql = f"INSERT OR IGNORE INTO jobs ({', '.join(JOB_COLUMNS)}) VALUES ({', '.join('?' * len(JOB_COLUMNS))})"
        with self._tx():
            before = self._con.total_changes
            self._con.executemany(sql, [_to_columns(r) for r in rows])
            return self._con.total_changes - before

    def jobs(self, *, kind: str | None = None, role: str | None = None, with_points: bool = False,
             with_trace: bool = True) -> list[JobRow]:
        """The stored :class:`JobRow` s, ordered by sample index, then insertion; ``points`` only when
        ``with_points`` (else None), ``trace`` only when ``with_trace`` (else empty)."""
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
        return [_from_columns(dict(zip(cols, r, strict=True))) for r in self._con.execute(sql, args)]

    def image_digests(self) -> dict[str, str]:
        """The SHA-256 of each sample's image file as its jobs read it (samples read from files only)."""
        return {r[0]: r[1] for r in self._con.execute("SELECT sample_id, sha256 FROM contents") if r[1]}

    def differing_pixels(self, other: ResultStore) -> list[str]:
        """The samples both stores read from files whose bytes differ (the same id, other pixels)."""
        mine, theirs = self.image_digests(), other.image_digests()
        return sorted(sid for sid, d in theirs.items() if sid in mine and mine[sid] != d)

    def check_mergeable(self, other: ResultStore, campaign: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """``ValueError`` unless ``other`` holds job rows of this store's campaign and detector (or of ``campaign``,
        when given: several sources checked against the first before anything is written) on samples that agree
        with this store's; returns ``other``'s campaign."""
        theirs = other.campaign()
        if theirs is None or other.count() == 0:
            raise ValueError(f"{other.path}: holds no job rows to merge")
        mine = campaign if campaign is not None else (self.campaign() if self.count() else None)
        if mine is not None:
            self._check_same(mine, theirs["spec"], theirs["detector"],
                             hint=f"{other.path} belongs to another campaign or detector: merge only runs of one")
        here = self.samples()
        clash = [sid for sid, s in other.samples().items() if sid in here
                 and (here[sid]["fingerprint"], here[sid]["sample_index"]) != (s["fingerprint"], s["sample_index"])]
        if clash:
            raise ValueError(f"{other.path}: samples {clash[:5]} differ from {self.path}'s (another image set)")
        pixels = self.differing_pixels(other)
        if pixels:
            raise ValueError(f"{other.path}: the image files of samples {pixels[:5]} differ from those {self.path}'s "
                             "jobs read (other pixels under the same names)")
        return theirs

    def merge(self, other: ResultStore, *, source: str = "") -> tuple[int, int]:
        """Copy into this store the job rows of ``other`` that it lacks, with their samples, image digests and runs —
        parts of one campaign computed elsewhere (another machine, a GPU, a cluster without a shared disk).

        ``other`` must hold the same campaign and detector (checked as a resuming run is: ``ValueError``); a sample
        both hold must have the same fingerprint and index. This store, when new, is bound to ``other``'s campaign.
        Each run of ``other`` that brought rows is recorded here anew (its provenance kept, ``config["merged_from"]``
        = ``source``), and the copied rows point to it. Rows already here (the same key: the same job, context and
        sample) are kept as they are. Returns (rows copied, rows already here). The caller holds the writer lock."""
        theirs = self.check_mergeable(other)
        if self.campaign() is None or self.count() == 0:
            self.bind_campaign(theirs["name"], theirs["spec"], theirs["detector"])
        have = self.done_keys()
        rows = [r for r in other.jobs(with_points=True) if r.key not in have]
        runs = {r["run_id"]: r for r in other.runs()}
        cols = ("started_at", "finished_at", "status", "code_version", "model_sha256", "detector_json", "dataset_id",
                "dataset_json", "config_json", "seed", "executor", "host", "jobs_total", "jobs_skipped", "jobs_done",
                "seconds")
        new_id: dict[int | None, int | None] = {None: None}
        with self._tx():
            for rid in sorted({r.run_id for r in rows if r.run_id is not None}):
                run = dict(runs.get(rid) or {"started_at": now_iso(), "status": "unknown"})
                run["config"] = {**(run.get("config") or {}), "merged_from": source or str(other.path)}
                vals = [_dumps(run.get(c.removesuffix("_json"))) if c.endswith("_json") else run.get(c) for c in cols]
                cur = self._con.execute(f"INSERT INTO runs ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
                                        vals)
                new_id[rid] = int(cur.lastrowid)
            self._con.executemany(
                f"INSERT OR IGNORE INTO jobs ({', '.join(JOB_COLUMNS)}) VALUES ({', '.join('?' * len(JOB_COLUMNS))})",
                [_to_columns(r.replace(run_id=new_id.get(r.run_id))) for r in rows])
            self._con.executemany("INSERT OR IGNORE INTO contents (sample_id, path, size, mtime_ns, sha256) "
                                  "VALUES (?, ?, ?, ?, ?)",
                                  other._con.execute("SELECT sample_id, path, size, mtime_ns, sha256 FROM contents"))
            self._insert_samples(other.samples().values())  # one transaction: all of it or nothing
        return len(rows), other.count() - len(rows)

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


def _detector_identity(detector: Mapping[str, Any]) -> dict[str, Any]:
    """What decides a detector's outputs, as a store compares it: its kind, model SHA-256 and options (design,
    oracle noise, crop window, …) — not the engine or device, which change speed and outputs by ≤ 1e-3 px only, so
    a run may resume or merge across them (CPU and GPU, ONNX Runtime and torch)."""
    options = {k: v for k, v in (detector.get("options") or {}).items() if k not in ("engine", "device")}
    return {"kind": detector.get("kind"), "sha256": detector.get("sha256"), "options": options}


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
