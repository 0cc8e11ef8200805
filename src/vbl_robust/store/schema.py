"""The layout of a results store (one SQLite file, ``results.sqlite``), declared once: each table as a tuple of
:class:`Column` s, from which its DDL, its migrations and the way a row goes in and comes out all follow.
Schema version :data:`SCHEMA_VERSION` in ``PRAGMA user_version``.

- ``campaign`` — the one campaign this store holds (spec JSON, detector identity); once a job row is stored, a
  run with different settings or another detector is refused, so a store never mixes incomparable results.
- ``runs`` — one row per invocation (:class:`~vbl_robust.store.rows.RunRecord`): code version, model
  file SHA-256, dataset identity, full config JSON, seed, executor, host, start/finish times, jobs done.
- ``samples`` — id, index, slant distance, envelope, size and a geometry fingerprint of each sample.
- ``contents`` — for a sample read from an image file: the file's SHA-256 (with its size and mtime, so it is
  recomputed only when they change): a rerun on changed pixels is refused instead of reusing results computed on
  the old ones.
- ``jobs`` — one row per finished job (:class:`~vbl_robust.store.rows.JobRow`), ``key`` UNIQUE: worst
  value and point, verdict, counts (failed evaluations per reason included), timings, the search trace (JSON) and
  every evaluated point with its failure reason and completion time (JSON, zlib-compressed), or a PnP payload
  (JSON).

Schema versions: 0/1 = before failures were recorded (no ``n_failed``, ``failures_json``, ``worst_reason``
columns: they are added on open, old rows read them as unknown); 2 = failures recorded; 3: every evaluated point
carries its completion time on the search's clock (``ts`` in the points blob, so no column is added; rows written
before read ``Points.times`` as None, and no time budget can be read off them); 4 = now: a main search job stores
the corners its detector predicted at the worst point (``worst_corners_json``, added on open; rows written before
read ``JobRow.worst_corners`` as None); 5 = now: every job row committed has a content digest in ``digests``
(:mod:`~vbl_robust.store.digest`), chained per run — no byte of the other tables changes; a store brought
to 5 records its rows stored before as ``before`` (written before digests, not covered). A column's ``since`` says
which version added it: :func:`migrate` adds the missing ones to an older store. A store written by a newer version
is refused with a one-line error.

- ``digests`` — one entry per job row committed (``stored``), per row forgotten to be run again (``forgotten``)
  and per row found by the migration to schema 5 (``before``): the SHA-256 of the row's stored columns (canonical
  JSON, blobs by their SHA-256), a short hash per column (which column changed), the SHA-256 of its sample's row,
  and the run's chain: each entry's ``chain_sha256`` hashes the run's previous one with this entry, so the run's
  last (its *head*) stands for every row the run committed, in order.
"""

from __future__ import annotations

import functools
import json
import sqlite3
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..search.result import TraceRow
from ..specs.budget import Budget
from ..specs.campaign import BoxSpec
from .rows import Corners, JobRow, Points, RunProvenance, RunRecord

#: Version of the layout below (``PRAGMA user_version``).
SCHEMA_VERSION = 5
#: The version from which every committed job row has its digest (``digests``).
DIGESTS_SINCE = 5


def _same(v: Any) -> Any:
    return v


def _json(v: Any) -> str | None:
    return None if v is None else json.dumps(v)


@functools.lru_cache(maxsize=4096)
def _box(text: str) -> BoxSpec:
    """A stored box, decoded once per distinct text: the rows of a campaign share a few boxes (frozen: one object
    serves every row, a large store's rows hold no copy each)."""
    return BoxSpec.from_dict(json.loads(text))


@functools.lru_cache(maxsize=4096)
def _budget(text: str) -> Budget:
    """A stored budget, decoded once per distinct text (as :func:`_box`)."""
    return Budget.from_dict(json.loads(text))


def _loads(v: str | None) -> Any:
    return None if v is None else json.loads(v)


def _dumps(v: Any) -> str | None:
    """A run's JSON column: keys sorted, what JSON cannot hold as its text."""
    return None if v is None else json.dumps(v, sort_keys=True, default=str)


def _dump_corners(c: Corners | None) -> str | None:
    return None if c is None else json.dumps([[float(u), float(v)] for u, v in c])


def _load_corners(v: str | None) -> Corners | None:
    d = _loads(v)
    return None if d is None else tuple((float(u), float(w)) for u, w in d)


@dataclass(frozen=True)
class Column:
    """One column: its declaration, the row field it holds (a dotted path into the row, "" = none: a column of a
    table without a row type) and how the value goes in (``dump``) and comes out (``load``; None: a column derived
    on write only, e.g. ``box_label`` for queries)."""

    name: str
    decl: str
    field: str = ""
    dump: Callable[[Any], Any] = _same
    load: Callable[[Any], Any] | None = _same
    comment: str = ""
    since: int = 0  # the schema version that added it (added to older stores on open)
    same_line: bool = False  # declared on the previous column's line (the DDL's text, as stores hold it)


@dataclass(frozen=True)
class Table:
    """A table's columns in order, and the statements after its ``CREATE TABLE`` (indexes)."""

    name: str
    columns: tuple[Column, ...]
    after: tuple[str, ...] = ()
    comment_at: int = 0  # where the columns' comments start (0: two spaces after the declaration)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    def column(self, name: str) -> Column:
        """The column ``name`` (``KeyError`` for none)."""
        return next(c for c in self.columns if c.name == name) if name in self.names else {}[name]

    def ddl(self) -> str:
        """``CREATE TABLE IF NOT EXISTS`` (and what follows it), one column a line with its comment."""
        lines: list[str] = []
        for i, c in enumerate(self.columns):
            text = f"{c.name} {c.decl}{',' if i < len(self.columns) - 1 else ''}"
            if c.same_line:
                lines[-1] += f" {text}"
                continue
            if c.comment:
                text = f"{text.ljust(max(self.comment_at, len(text) + 2))}-- {c.comment}"
            lines.append(f"    {text}")
        return "\n".join((f"CREATE TABLE IF NOT EXISTS {self.name} (", *lines, ");", *self.after))

    def insert(self, names: Iterable[str] | None = None, *, verb: str = "INSERT") -> str:
        """``{verb} INTO`` the columns ``names`` (default: all), one ``?`` each."""
        names = tuple(self.names if names is None else names)
        return f"{verb} INTO {self.name} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})"


CAMPAIGN = Table("campaign", (
    Column("id", "INTEGER PRIMARY KEY CHECK (id = 1)"),
    *(Column(n, "TEXT NOT NULL") for n in ("name", "spec_json", "detector_json", "created_at")),
))

#: The runs table: a :class:`RunRecord`'s fields (``provenance.*``: its :class:`RunProvenance`'s).
RUNS = Table("runs", (
    Column("run_id", "INTEGER PRIMARY KEY AUTOINCREMENT", "run_id"),
    Column("started_at", "TEXT NOT NULL", "started_at"),
    Column("finished_at", "TEXT", "finished_at"),
    Column("status", "TEXT NOT NULL", "status", lambda st: st.value),
    Column("code_version", "TEXT", "provenance.code_version"),
    Column("model_sha256", "TEXT", "provenance.model_sha256"),
    Column("detector_json", "TEXT", "provenance.detector", _dumps, _loads),
    Column("dataset_id", "TEXT", "provenance.dataset_id"),
    Column("dataset_json", "TEXT", "provenance.dataset", _dumps, _loads),
    Column("config_json", "TEXT", "provenance.config", _dumps, _loads),
    Column("seed", "INTEGER", "provenance.seed"),
    Column("executor", "TEXT", "provenance.executor"),
    Column("host", "TEXT", "provenance.host"),
    Column("jobs_total", "INTEGER", "provenance.jobs_total"),
    Column("jobs_skipped", "INTEGER", "provenance.jobs_skipped"),
    Column("jobs_done", "INTEGER DEFAULT 0", "jobs_done"),
    Column("seconds", "REAL", "seconds"),
))

SAMPLES = Table("samples", (
    Column("sample_id", "TEXT PRIMARY KEY"),
    Column("sample_index", "INTEGER"),
    Column("slant_distance_m", "REAL"),
    Column("envelope", "TEXT"),
    Column("width", "INTEGER"),
    Column("height", "INTEGER"),
    Column("fingerprint", "TEXT"),
    Column("meta_json", "TEXT"),
))

CONTENTS = Table("contents", (
    Column("sample_id", "TEXT PRIMARY KEY", comment="a sample read from an image file: what its pixels were"),
    Column("path", "TEXT"),
    Column("size", "INTEGER", same_line=True),
    Column("mtime_ns", "INTEGER", same_line=True),
    Column("sha256", "TEXT", comment="of the file's bytes; recomputed only when size or mtime changed"),
), comment_at=32)

#: The jobs table, in column order: the one place a job field is declared, written and read.
JOBS = Table("jobs", (
    Column("key", "TEXT NOT NULL UNIQUE", "key"),
    Column("run_id", "INTEGER", "run_id"),
    *(Column(n, "TEXT", n) for n in ("experiment", "kind", "role", "method", "sample_id")),
    Column("sample_index", "INTEGER", "sample_index"),
    Column("box_label", "TEXT", "box_label", load=None),
    Column("box_level", "REAL", "box_level", load=None),
    Column("box_json", "TEXT", "box", lambda b: None if b is None else json.dumps(b.to_dict()),
           lambda v: None if v is None else _box(v)),
    Column("budget_label", "TEXT", "budget_label", load=None),
    Column("budget_json", "TEXT", "budget", lambda b: None if b is None else json.dumps(b.to_dict()),
           lambda v: None if v is None else _budget(v)),
    Column("seed", "INTEGER", "seed"),
    Column("options_json", "TEXT", "options", lambda o: json.dumps(dict(o)), lambda v: _loads(v) or {}),
    Column("chain", "TEXT", "chain"),
    Column("status", "TEXT NOT NULL", "status", lambda st: st.value, comment="done | failed | implied"),
    Column("reason", "TEXT", "reason", comment="why a job failed / what implied it"),
    Column("worst_m", "REAL", "worst_m", comment="worst error found (m); the penalty for a failed sample"),
    Column("worst_x_json", "TEXT", "worst_x", lambda x: _json(None if x is None else dict(x)), _loads,
           comment="{name: value} of the worst point, real units"),
    Column("verdict", "TEXT", "verdict", lambda v: None if v is None else v.value,
           comment="breach | no breach found | certified | failed"),
    Column("nfev", "INTEGER", "nfev", load=lambda v: v or 0),
    Column("nit", "INTEGER", "nit", load=lambda v: v or 0),
    Column("search_status", "TEXT", "search_status"),
    Column("message", "TEXT", "message"),
    Column("search_s", "REAL", "search_s", comment="seconds inside the search (objective calls included)"),
    Column("job_s", "REAL", "job_s", comment="seconds for the whole job (objective building included)"),
    *(Column(n, "REAL", n) for n in ("upper_bound", "bound_estimate", "lipschitz_estimate")),
    Column("trace_json", "TEXT", "trace", lambda tr: json.dumps([t.to_dict() for t in tr]) if tr else None,
           lambda v: tuple(TraceRow.from_dict(t) for t in _loads(v) or ())),
    Column("points", "BLOB", "points", lambda pt: None if pt is None else pt.to_blob(),
           lambda v: Points.from_blob(v) if v else None,
           comment='zlib(JSON {"xs": [[...]], "fs": [...], "reasons": [...], "ts": [...]})'),
    Column("payload_json", "TEXT", "payload", _json, _loads,
           comment="PnP comparison results, details of the worst point"),
    Column("finished_at", "TEXT", "finished_at"),
    Column("n_failed", "INTEGER", "n_failed", comment="failed evaluations (schema 2)", since=2),
    Column("failures_json", "TEXT", "failures", lambda f: json.dumps(dict(f)) if f else None,
           lambda v: _loads(v) or {}, comment="{reason: count} of the failed evaluations (schema 2)", since=2),
    Column("worst_reason", "TEXT", "worst_reason", since=2,
           comment='failure reason at the worst point, "" = a successful evaluation (schema 2)'),
    Column("worst_corners_json", "TEXT", "worst_corners", _dump_corners, _load_corners, since=4,
           comment="[[u, v] x 4] corners predicted at the worst point, sample's pixels (schema 4)"),
), after=("CREATE INDEX IF NOT EXISTS jobs_by_sample ON jobs (sample_id);",))

#: The digests of the job rows as committed (schema 5; :mod:`~vbl_robust.store.digest`): a table of its
#: own, so that no byte of the jobs table changes.
DIGESTS = Table("digests", (
    Column("seq", "INTEGER PRIMARY KEY AUTOINCREMENT", comment="order of writing"),
    Column("event", "TEXT NOT NULL", comment="stored | forgotten | before (a row stored before schema 5)"),
    Column("key", "TEXT NOT NULL", comment="the job row's key"),
    Column("run_id", "INTEGER", comment="the chain it belongs to: the row's run"),
    Column("layout", "INTEGER", comment="the schema version whose job columns the digest covers"),
    Column("row_sha256", "TEXT", comment="SHA-256 of the row's columns (canonical JSON, blobs by SHA-256)"),
    Column("columns", "TEXT", comment="a short hash per column, in column order (names the column changed)"),
    Column("sample_sha256", "TEXT", comment="SHA-256 of its sample's row when committed (None: not stored)"),
    Column("chain_sha256", "TEXT NOT NULL", comment="SHA-256 of the run's previous chain_sha256 and this entry"),
), after=("CREATE INDEX IF NOT EXISTS digests_by_key ON digests (key);",
          "CREATE INDEX IF NOT EXISTS digests_by_run ON digests (run_id, seq);"), comment_at=40)

#: Every table, in the order of the DDL.
TABLES = (CAMPAIGN, RUNS, SAMPLES, CONTENTS, JOBS, DIGESTS)

#: The whole layout of a new store (``CREATE … IF NOT EXISTS``: run on every open).
DDL = "\n" + "\n".join(t.ddl() for t in TABLES) + "\n"

JOB_COLUMNS = JOBS.names


def _get(row: Any, path: str) -> Any:
    for part in path.split("."):
        row = getattr(row, part)
    return row


def to_columns(table: Table, row: Any, names: Iterable[str] | None = None) -> tuple[Any, ...]:
    """The stored values of ``row`` (a :class:`JobRow` for :data:`JOBS`, a :class:`RunRecord` for :data:`RUNS`) in
    the columns ``names`` (default: all)."""
    names = table.names if names is None else tuple(names)
    by = {c.name: c for c in table.columns}
    return tuple(by[n].dump(_get(row, by[n].field)) for n in names)


def job_row(d: Mapping[str, Any], **read: Any) -> JobRow:
    """A job row from the columns read (``points`` / ``trace_json`` may be left out: None / empty); ``read``: fields
    given already read, e.g. ``points`` / ``trace`` left in the store (:class:`~.rows.StoredPoints`,
    :class:`~.rows.StoredTrace`)."""
    return JobRow(**{c.field: c.load(d[c.name]) for c in JOBS.columns if c.load is not None and c.name in d}, **read)


def run_record(d: Mapping[str, Any]) -> RunRecord:
    """A run from its columns (all of them)."""
    values = {c.field: c.load(d[c.name]) for c in RUNS.columns if c.load is not None}
    prov = {k.removeprefix("provenance."): v for k, v in values.items() if k.startswith("provenance.")}
    return RunRecord(provenance=RunProvenance(**prov), **{k: v for k, v in values.items() if "." not in k})


class Transaction:
    """``BEGIN IMMEDIATE`` … ``COMMIT`` (``ROLLBACK`` on error)."""

    def __init__(self, con: sqlite3.Connection):
        self.con = con

    def __enter__(self) -> None:
        self.con.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type: object, *_: object) -> None:
        self.con.execute("ROLLBACK" if exc_type is not None else "COMMIT")


def schema_version(con: sqlite3.Connection, path: str | Path) -> int:
    """The store's schema version; a newer one than :data:`SCHEMA_VERSION` closes ``con`` and is refused
    (``ValueError``)."""
    version = int(con.execute("PRAGMA user_version").fetchone()[0])
    if version > SCHEMA_VERSION:
        con.close()
        raise ValueError(f"{path}: results store schema version {version} is newer than this vbl-robust's "
                         f"({SCHEMA_VERSION}); upgrade vbl-robust to read it")
    return version


def migrate(con: sqlite3.Connection, path: str | Path,
            before_digests: Callable[[sqlite3.Connection], None] | None = None) -> None:
    """Create the tables of a new store; bring an older one to :data:`SCHEMA_VERSION` (adds the columns of the
    versions since; ``ValueError`` for a newer one). ``before_digests`` records the rows of a store older than
    :data:`DIGESTS_SINCE` as written before digests (:func:`~vbl_robust.store.digest.mark_before`, passed
    in by the store: the digests' module builds on this one)."""
    version = schema_version(con, path)
    con.executescript(DDL)
    if version == SCHEMA_VERSION:
        return
    with Transaction(con):
        for table in TABLES:
            added = [c for c in table.columns if c.since]
            have = {r[1] for r in con.execute(f"PRAGMA table_info({table.name})")} if added else set()
            for c in added:
                if c.name not in have:
                    con.execute(f"ALTER TABLE {table.name} ADD COLUMN {c.name} {c.decl}")
        if version < DIGESTS_SINCE and before_digests is not None:
            before_digests(con)
        con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
