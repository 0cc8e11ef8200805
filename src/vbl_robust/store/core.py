"""The SQLite results store: one :class:`~vbl_robust.store.rows.JobRow` per finished job, provenance per
run, resumable and crash-safe (the tables: :mod:`~vbl_robust.store.schema`).

Crash safety: WAL journal, one transaction per finished job (``INSERT OR IGNORE`` on the key). A process killed at
any moment (``kill -9``) loses only the job in progress; committed rows stay and a rerun inserts no duplicates.
Only a writer holding the store's :class:`~vbl_robust.store.lock.WriterLock` writes.
"""

from __future__ import annotations

import json
import sqlite3
from collections import OrderedDict
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from stat import S_ISREG
from typing import TYPE_CHECKING, Any

from .digest import mark_before, record_forgotten, record_stored
from .identity import check_same
from .rows import (
    JobRow,
    JobStatus,
    Points,
    RunProvenance,
    RunRecord,
    RunStatus,
    SampleRecord,
    StoredCampaign,
    StoredPoints,
    StoredTrace,
    now_iso,
)
from .schema import (
    CAMPAIGN,
    CONTENTS,
    DIGESTS,
    JOBS,
    RUNS,
    SAMPLES,
    SCHEMA_VERSION,
    Transaction,
    job_row,
    migrate,
    run_record,
    schema_version,
    to_columns,
)

if TYPE_CHECKING:
    from ..specs.campaign import CampaignSpec

#: File name of the store in a run directory.
STORE = "results.sqlite"
#: File name of a packed store (xz) in a bundle (:func:`~vbl_robust.store.pack.pack_store`).
PACKED = STORE + ".xz"
#: Bytes read at a time when a packed store is unpacked (bounded memory, whatever the store's size).
_UNPACK_CHUNK = 1 << 20
#: Bytes of decoded points and traces a store read on demand keeps for the rows read last
#: (:attr:`ResultStore.points_on_demand`): what bounds a report's memory whatever the store's size.
POINTS_CACHE_BYTES = 64 << 20


def unpack(packed: Path, target: Path) -> Path:
    """Decompress the packed store ``packed`` (xz) into the file ``target``, streamed in chunks of
    :data:`_UNPACK_CHUNK` bytes (memory bounded whatever the store's size); ``ValueError`` (one line, ``target``
    removed) for a file that is not a complete xz stream."""
    import lzma
    import shutil

    try:
        with lzma.open(packed, "rb") as src, open(target, "wb") as dst:
            shutil.copyfileobj(src, dst, _UNPACK_CHUNK)
    except (lzma.LZMAError, EOFError) as exc:
        Path(target).unlink(missing_ok=True)
        raise ValueError(f"{packed}: not a complete packed store ({exc})") from None
    except BaseException:
        Path(target).unlink(missing_ok=True)
        raise
    return Path(target)


def _nbytes(v: Any, raw: Any = None) -> int:
    """About what a decoded column holds: points their arrays and a reason string per point; a trace ten times
    its JSON text (``raw``), which its objects take about."""
    if isinstance(v, Points):
        return v.xs.nbytes + v.fs.nbytes + (0 if v.times is None else v.times.nbytes) + 64 * len(v.reasons)
    return 10 * len(raw or "")


#: The rows of jobs not measured (one ``?``: ``JobStatus.NOT_MEASURED``); "failed" was their status's name in
#: stores written before it.
_UNMEASURED = "status IN (?, 'failed')"


class ResultStore:
    """A campaign's results in one SQLite file (see :mod:`~vbl_robust.store.schema` for the layout).

    >>> import tempfile, pathlib
    >>> store = ResultStore(pathlib.Path(tempfile.mkdtemp()) / "results.sqlite")
    >>> store.count()
    0
    """

    def __init__(self, path: str | Path, *, readonly: bool = False, points_on_demand: bool = False):
        self.path = Path(path)
        self.readonly = readonly
        #: :meth:`jobs` leaves each row's points and trace in the store until they are read
        #: (:class:`~.rows.StoredPoints`, :class:`~.rows.StoredTrace`, through a cache bounded by
        #: :data:`POINTS_CACHE_BYTES`): a reader of a store of any size holds no row's evaluations. Read-only stores
        #: only, and the rows' points read while the store is open.
        self.points_on_demand = points_on_demand and readonly
        self._unpacked_dir: Path | None = None  # a packed store read through a temporary copy (removed at close)
        # decoded columns on demand by (column, rowid), least recent first (points_on_demand)
        self._cache: OrderedDict[tuple[str, int], tuple[Any, int]] = OrderedDict()  # (value, bytes)
        self._cache_bytes = 0
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
                migrate(self._con, self.path, mark_before)
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
                version = schema_version(con, self.path)
            except sqlite3.OperationalError:
                con.close()
                con = None
        if con is None:
            con = sqlite3.connect(f"{uri}?mode=ro&immutable=1", uri=True, isolation_level=None)
            version = schema_version(con, self.path)
        if version < SCHEMA_VERSION:
            mem = sqlite3.connect(":memory:", isolation_level=None)
            con.backup(mem)
            con.close()
            con = mem
            migrate(con, self.path, mark_before)
        con.execute("PRAGMA query_only = ON")
        return con

    @classmethod
    def open_existing(cls, path: str | Path, *, readonly: bool = True, points_on_demand: bool = False) -> ResultStore:
        """Open a store that must exist (a run directory or the ``.sqlite`` file itself) — read-only unless told
        otherwise: reading a run (report, zones, tables, bundles) never writes it, and works where it cannot.
        Read-only, a packed store (``results.sqlite.xz`` of a bundle, named or found in the run directory instead of
        ``results.sqlite``) is read through a temporary unpacked copy, removed when the store is closed.
        ``points_on_demand``: see :attr:`points_on_demand` (what the report and the bundle read with)."""
        p = Path(path)
        if p.is_dir():
            p = p / STORE
        packed = p if p.name.endswith(".xz") else p.with_name(p.name + ".xz")
        if not p.is_file() or p.name.endswith(".xz"):
            if packed.is_file() and readonly:
                return cls._unpacked(packed, points_on_demand)
            hint = (f"; {packed.name} beside it is packed: `vbl-robust merge {packed} --into DIR` unpacks it into a "
                    "run directory") if packed.is_file() else " (run `vbl-robust audit` or `reproduce` with --out first)"
            raise FileNotFoundError(f"{p}: no results store{hint}")
        return cls(p, readonly=readonly, points_on_demand=points_on_demand)

    @classmethod
    def _unpacked(cls, packed: Path, points_on_demand: bool = False) -> ResultStore:
        """A packed store opened read-only through a temporary copy (streamed: bounded memory)."""
        import shutil
        import tempfile

        tmp = Path(tempfile.mkdtemp(prefix="vbl-robust-store-"))
        try:
            unpack(packed, tmp / STORE)
            store = cls(tmp / STORE, readonly=True, points_on_demand=points_on_demand)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        store._unpacked_dir = tmp
        return store

    def close(self) -> None:
        self._con.close()
        if self._unpacked_dir is not None:
            import shutil

            shutil.rmtree(self._unpacked_dir, ignore_errors=True)
            self._unpacked_dir = None

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def transaction(self) -> Transaction:
        """One write transaction (``with store.transaction(): …``): all of it or nothing."""
        return Transaction(self._con)

    # -- campaign -------------------------------------------------------------------------------------------
    def campaign(self) -> StoredCampaign | None:
        """The stored campaign, or None for a new store (readers outside the store ask :meth:`spec` or
        :meth:`require_campaign`, which say in one line that there is none)."""
        row = self._con.execute("SELECT name, spec_json, detector_json, created_at FROM campaign WHERE id = 1").fetchone()
        if row is None:
            return None
        return StoredCampaign(row[0], json.loads(row[1]), json.loads(row[2]), row[3])

    def holds_campaign(self) -> bool:
        """Whether a campaign is stored (a store nothing was run into holds none)."""
        return self._con.execute("SELECT 1 FROM campaign WHERE id = 1").fetchone() is not None

    def require_campaign(self) -> StoredCampaign:
        """The stored campaign (:meth:`campaign`); ``ValueError`` (one line) for a store that holds none — a 0-byte
        file, or a store nothing was run into (left by a command refused before its run, or a refused merge):
        there is nothing to read."""
        camp = self.campaign()
        if camp is None:
            raise ValueError(f"{self.path}: the results store holds no campaign yet (nothing was run into it)")
        return camp

    def spec(self) -> CampaignSpec:
        """The stored campaign's spec; ``ValueError`` (one line, :meth:`require_campaign`) for a store that holds
        none."""
        return self.require_campaign().spec

    def bind_campaign(self, name: str, spec: Mapping[str, Any], detector: Mapping[str, Any]) -> None:
        """Bind the store to a campaign and detector, or check that it holds this one.

        A store is bound by what was computed in it: while it holds no job row (a new store, or a run that
        failed before its first job, e.g. on a refused model file), the campaign and detector are recorded
        anew and samples recorded by that run are forgotten. Once it holds a job row, another campaign (spec,
        :data:`~vbl_robust.store.identity.PRESENTATION_KEYS` aside) or another detector (kind, model
        SHA-256 and options such as the design or the oracle's noise:
        :func:`~vbl_robust.store.identity.detector_identity`) is refused (``ValueError``).
        """
        have = self.campaign()
        spec_j = json.dumps(spec, sort_keys=True)
        det_j = json.dumps(detector, sort_keys=True)
        bound = have is not None and self.count() > 0
        if bound:
            check_same(self.path, have, spec, detector)
        with self.transaction():
            if not bound:
                self._con.execute("DELETE FROM samples")
            created = have.created_at if bound else now_iso()
            self._con.execute(CAMPAIGN.insert(verb="INSERT OR REPLACE"), (1, name, spec_j, det_j, created))

    # -- runs -----------------------------------------------------------------------------------------------
    def begin_run(self, provenance: RunProvenance) -> int:
        """Insert a run row (status "running") and return its id. Called under the store's writer lock
        (:func:`~vbl_robust.campaigns.runner.run_campaign`), so an earlier run still marked "running" has ended
        without recording it (SIGKILL, a machine's or session's end): it is closed first as "killed", finished at
        its last stored job, its seconds up to that job (:meth:`close_killed_runs`)."""
        self.close_killed_runs()
        with self.transaction():
            return self.insert_run(RunRecord(None, now_iso(), RunStatus.RUNNING, provenance, jobs_done=0))

    def insert_run(self, run: RunRecord) -> int:
        """Store ``run`` as a new run (its ``run_id`` aside: a new one is given), inside the caller's transaction;
        returns its id."""
        names = RUNS.names[1:]
        return int(self._con.execute(RUNS.insert(names), to_columns(RUNS, run, names)).lastrowid)

    def close_killed_runs(self) -> int:
        """Mark every run still "running" as "killed": finished at its last stored job (its start if none), its
        jobs done and its seconds up to then. Only a writer holding the store's lock may call it (a run in progress
        elsewhere would be closed too); returns how many runs it closed."""
        last = "(SELECT max(j.finished_at) FROM jobs j WHERE j.run_id = runs.run_id)"
        with self.transaction():
            cur = self._con.execute(
                f"UPDATE runs SET status = ?, finished_at = coalesce({last}, started_at), "
                "jobs_done = (SELECT count(*) FROM jobs j WHERE j.run_id = runs.run_id), "
                f"seconds = max(0.0, 86400.0 * (julianday(coalesce({last}, started_at)) - julianday(started_at))) "
                "WHERE status = ?", (RunStatus.KILLED.value, RunStatus.RUNNING.value))
        return cur.rowcount

    def end_run(self, run_id: int, status: RunStatus, jobs_done: int, seconds: float) -> None:
        with self.transaction():
            self._con.execute("UPDATE runs SET finished_at = ?, status = ?, jobs_done = ?, seconds = ? WHERE run_id = ?",
                              (now_iso(), RunStatus(status).value, jobs_done, seconds, run_id))

    def runs(self) -> list[RunRecord]:
        """Every run, oldest first."""
        cur = self._con.execute(f"SELECT {', '.join(RUNS.names)} FROM runs ORDER BY run_id")
        return [run_record(dict(zip(RUNS.names, r, strict=True))) for r in cur.fetchall()]

    # -- samples ------------------------------------------------------------------------------------------
    def add_samples(self, records: Iterable[SampleRecord]) -> None:
        with self.transaction():
            self.insert_samples(records)

    def insert_samples(self, records: Iterable[SampleRecord]) -> None:
        """The samples' records (a sample already stored is kept), inside the caller's transaction."""
        self._con.executemany(SAMPLES.insert(verb="INSERT OR IGNORE"), [tuple(getattr(r, c) for c in SAMPLES.names)
                                                                        for r in records])

    def samples(self) -> dict[str, SampleRecord]:
        """Every stored sample by id, in sample index order."""
        cur = self._con.execute(f"SELECT {', '.join(SAMPLES.names)} FROM samples ORDER BY sample_index")
        return {r[0]: SampleRecord(**dict(zip(SAMPLES.names, r, strict=True))) for r in cur.fetchall()}

    def check_contents(self, samples: Iterable[Any], digests: Mapping[str, str] | None = None) -> None:
        """Record the image-file digest of each sample (each frame of a sequence) read from a file (``image_path``), and refuse
        (``ValueError`` naming them) samples whose file's bytes differ from those their stored jobs were computed
        on. Every file is hashed on every run: a size and mtime that did not change prove nothing (``cp -p``,
        ``tar x`` and ``rsync -a`` keep them for other bytes); samples rendered in memory have no file (their pixels
        follow from their geometry and the generator, both in the job keys and the provenance). ``digests``
        (sample id → hex SHA-256) are this run's digests already computed from the files' bytes (the pre-run image
        check, :func:`vbl_robust.data.check.image_digests`): those files are not read again."""
        rows = self.changed_contents(samples, digests)
        with self.transaction():
            self.insert_contents(rows, replace=True)

    def changed_contents(self, samples: Iterable[Any], digests: Mapping[str, str] | None = None,
                         ) -> list[tuple[Any, ...]]:
        """What :meth:`check_contents` checks, without writing: ``ValueError`` for samples whose file's bytes
        differ from those their stored jobs were computed on, else the ``contents`` rows of this run's files."""
        from ..digest import file_sha256

        stored = {r[0]: r[1:] for r in self.contents()}
        with_jobs = {r[0] for r in self._con.execute("SELECT DISTINCT sample_id FROM jobs")}
        changed, rows = [], []
        for owner in samples:  # a sequence campaign's sample is an approach sequence: each frame has its file
            for s in getattr(owner, "samples", None) or (owner,):
                path = getattr(s, "image_path", None)
                try:
                    st = None if path is None else Path(path).stat()
                except OSError:  # missing, or a name the file system refuses (too long …)
                    st = None
                if st is None or not S_ISREG(st.st_mode):
                    continue  # rendered in memory, or not a readable file (the job records that failure)
                old = stored.get(s.id)
                digest = (digests or {}).get(s.id) or file_sha256(path)
                if old is not None and old[3] != digest and owner.id in with_jobs:
                    changed.append(f"{s.id} ({path})")
                    continue
                rows.append((s.id, str(path), st.st_size, st.st_mtime_ns, digest))
        if changed:
            raise ValueError(f"{self.path}: the pixels of {len(changed)} sample(s) changed since their results were "
                             f"stored: {', '.join(changed[:5])}{' …' if len(changed) > 5 else ''}; run them into "
                             "another --out (the stored results describe the old images)")
        return rows

    def contents(self) -> list[tuple[Any, ...]]:
        """The ``contents`` rows: ``(sample_id, path, size, mtime_ns, sha256)`` of each sample read from a file."""
        return self._con.execute(f"SELECT {', '.join(CONTENTS.names)} FROM contents").fetchall()

    def insert_contents(self, rows: Iterable[Sequence[Any]], *, replace: bool = False) -> None:
        """``contents`` rows (as :meth:`contents` gives them), inside the caller's transaction; a sample's stored
        row is kept unless ``replace``."""
        self._con.executemany(CONTENTS.insert(verb="INSERT OR REPLACE" if replace else "INSERT OR IGNORE"), rows)

    def image_digests(self) -> dict[str, str]:
        """The SHA-256 of each sample's image file as its jobs read it (samples read from files only)."""
        return {r[0]: r[1] for r in self._con.execute("SELECT sample_id, sha256 FROM contents") if r[1]}

    def differing_pixels(self, other: ResultStore) -> list[str]:
        """The samples both stores read from files whose bytes differ (the same id, other pixels)."""
        mine, theirs = self.image_digests(), other.image_digests()
        return sorted(sid for sid, d in theirs.items() if sid in mine and mine[sid] != d)

    # -- jobs ---------------------------------------------------------------------------------------------
    def done_keys(self) -> set[str]:
        return {r[0] for r in self._con.execute("SELECT key FROM jobs")}

    def count(self) -> int:
        return int(self._con.execute("SELECT COUNT(*) FROM jobs").fetchone()[0])

    def forget_failed(self) -> int:
        """Delete the rows of jobs not measured (the tool could not complete them: status "not measured", or "failed"
        in stores written before the name), so that a rerun runs them again; returns how many were deleted. Each
        leaves a ``forgotten`` digest entry in its run's chain (:mod:`~vbl_robust.store.digest`)."""
        where = f"WHERE {_UNMEASURED}"
        with self.transaction():
            gone = self._con.execute(f"SELECT key, run_id FROM jobs {where} ORDER BY rowid",
                                     (JobStatus.NOT_MEASURED.value,)).fetchall()
            record_forgotten(self._con, gone)
            before = self._con.total_changes
            self._con.execute(f"DELETE FROM jobs {where}", (JobStatus.NOT_MEASURED.value,))
            return self._con.total_changes - before

    def commit(self, rows: Sequence[JobRow]) -> int:
        """Insert the rows of finished jobs in one transaction; returns how many were new (duplicates ignored). Each
        new row gets its digest, chained in its run (:mod:`~vbl_robust.store.digest`)."""
        if not rows:
            return 0
        with self.transaction():
            return self.insert_jobs(rows)

    def insert_jobs(self, rows: Iterable[JobRow]) -> int:
        """Job rows (a key already stored is kept as it is), each new one with its digest entry, inside the caller's
        transaction; returns how many were new."""
        sql, new = JOBS.insert(verb="INSERT OR IGNORE"), 0
        for r in rows:
            cur = self._con.execute(sql, to_columns(JOBS, r))
            if cur.rowcount == 1:
                record_stored(self._con, int(cur.lastrowid))
                new += 1
        return new

    def jobs(self, *, kind: str | None = None, role: str | None = None, with_points: bool = False,
             with_trace: bool = True, measured: bool | None = None) -> list[JobRow]:
        """The stored :class:`JobRow` s, ordered by sample index, then insertion; ``points`` only when
        ``with_points`` (else None), ``trace`` only when ``with_trace`` (else empty); ``measured``: only the jobs
        the tool completed (True) or only those it could not (False: :attr:`JobRow.measured`)."""
        return list(self.iter_jobs(kind=kind, role=role, with_points=with_points, with_trace=with_trace,
                                   measured=measured))

    def iter_jobs(self, *, kind: str | None = None, role: str | None = None, with_points: bool = False,
                  with_trace: bool = True, measured: bool | None = None) -> Iterator[JobRow]:
        """:meth:`jobs` one row at a time (what a reader that needs no list of every row reads: a large store's
        export)."""
        where, args = [], []
        if measured is not None:
            where.append(_UNMEASURED if not measured else f"NOT {_UNMEASURED}")
            args.append(JobStatus.NOT_MEASURED.value)
        if kind is not None:
            where.append("kind = ?")
            args.append(kind)
        if role is not None:
            where.append("role = ?")
            args.append(role)
        # on demand: points and trace stay in the store until read (StoredPoints, StoredTrace); only whether a row
        # has any is read now
        lazy = self.points_on_demand
        cols = [c for c in JOBS.names if (with_points and not lazy or c != "points")
                and (with_trace and not lazy or c != "trace_json")]
        lead = ["rowid", "points IS NOT NULL AND length(points) > 0", "trace_json IS NOT NULL AND trace_json != '[]'"]
        lead = lead if lazy else []
        sql = f"SELECT {', '.join(lead + cols)} FROM jobs" + (f" WHERE {' AND '.join(where)}" if where else "")
        sql += " ORDER BY sample_index, rowid"
        for r in self._con.execute(sql, args):
            d = dict(zip(cols, r[len(lead):], strict=True))
            if d["key"] in self._left_out:
                continue
            read = {}
            if lazy and with_points and r[1]:
                read["points"] = StoredPoints(partial(self._on_demand, "points", r[0]))
            if lazy and with_trace and r[2]:
                read["trace"] = StoredTrace(partial(self._on_demand, "trace_json", r[0]))
            yield job_row(d, **read)

    def forget_points(self) -> None:
        """Empty the cache of points and traces read on demand (they are read again when asked for)."""
        self._cache.clear()
        self._cache_bytes = 0

    def _column_at(self, column: str, rowid: int) -> Any:
        return self._con.execute(f"SELECT {column} FROM jobs WHERE rowid = ?", (rowid,)).fetchone()[0]

    def _on_demand(self, column: str, rowid: int, raw: bool = False) -> Any:
        """The decoded ``points`` or ``trace_json`` of the job row ``rowid`` (:class:`~.rows.StoredPoints`,
        :class:`~.rows.StoredTrace`), through a cache of the last ones read, bounded by
        :data:`POINTS_CACHE_BYTES`; ``raw``: the stored value itself."""
        if raw:
            return self._column_at(column, rowid)
        key = (column, rowid)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit[0]
        raw = self._column_at(column, rowid)
        v = JOBS.column(column).load(raw)
        self._cache[key] = (v, _nbytes(v, raw))
        self._cache_bytes += self._cache[key][1]
        while self._cache_bytes > POINTS_CACHE_BYTES and len(self._cache) > 1:
            self._cache_bytes -= self._cache.popitem(last=False)[1][1]
        return v

    # -- verification (:mod:`~vbl_robust.campaigns.verify`) --------------------------------------------------------
    #: Keys of rows found inconsistent (:meth:`leave_out`): :meth:`jobs` leaves them out.
    _left_out: frozenset[str] = frozenset()

    def leave_out(self, keys: Iterable[str]) -> None:
        """From now on :meth:`jobs` leaves out the rows ``keys`` (rows found inconsistent with their own evaluations
        or their digests: :func:`vbl_robust.campaigns.verify.screen`); ``count`` still counts them."""
        self._left_out = frozenset(keys)

    @property
    def left_out(self) -> frozenset[str]:
        return self._left_out

    @property
    def changes(self) -> int:
        """Rows this connection has changed since it was opened (a check of the rows read before is stale)."""
        return self._con.total_changes

    @contextmanager
    def snapshot(self) -> Iterator[None]:
        """Inside: every read sees the store as of one moment (a read transaction: rows a writer commits meanwhile,
        with their digests, are not half seen). Nested in a transaction already open: that one."""
        if self._con.in_transaction:
            yield
            return
        self._con.execute("BEGIN")
        try:
            yield
        finally:
            self._con.execute("COMMIT")

    def job_columns(self) -> Iterator[dict[str, Any]]:
        """Every job row's stored columns as SQLite returns them (``{column: value}``, blobs as bytes), in insertion
        order, one at a time: what a check reads before anything is decoded."""
        cur = self._con.execute(f"SELECT {', '.join(JOBS.names)} FROM jobs ORDER BY rowid")
        for r in cur:
            yield dict(zip(JOBS.names, r, strict=True))

    def digest_entries(self) -> Iterator[dict[str, Any]]:
        """The ``digests`` rows in the order written (:mod:`~vbl_robust.store.digest`)."""
        for r in self._con.execute(f"SELECT {', '.join(DIGESTS.names)} FROM digests ORDER BY seq"):
            yield dict(zip(DIGESTS.names, r, strict=True))

    def digest_heads(self) -> dict[int | None, str]:
        """Each run's head (its last chain value) as stored."""
        return dict(self._con.execute("SELECT run_id, chain_sha256 FROM digests WHERE seq IN "
                                      "(SELECT max(seq) FROM digests GROUP BY run_id) ORDER BY run_id").fetchall())
