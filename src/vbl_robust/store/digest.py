"""Content digests of the job rows, chained per run: written when a row is committed, checked by ``vbl-robust
verify`` (:func:`vbl_robust.campaigns.verify.check_store`), so a store someone files can be checked by anyone later.

A row's digest is the SHA-256 of its stored columns as canonical JSON (keys sorted, no spaces, ASCII; a blob — the
points — by its own SHA-256; a non-finite float by its name), over the job columns of the layout it was written
with (``layout``: the schema version). Beside it, a short hash per column names the column that changed. The
digest of the row's sample (its ``samples`` row) is kept too.

Each run is a chain: an entry's ``chain_sha256`` is the SHA-256 of the run's previous ``chain_sha256`` and the
entry's fields, so the run's last value — its *head* — stands for every row the run committed, in order (a report
prints the heads, :func:`store_head`; a changed row, or a changed entry, changes it). Entries are ``stored`` (a row
committed), ``forgotten`` (a row not measured, deleted to be run again: ``ResultStore.forget_failed``) or
``before`` (a row stored before digests were written, schema < 5: recorded by the migration, not covered).

Checking (:func:`read_chains`, :func:`check_row`) needs no recomputation of the searches: it compares what is
stored with what was committed. The digests are a table of their own (``digests``), so that no byte of the other
tables changes.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from .schema import DIGESTS, JOBS, SAMPLES, SCHEMA_VERSION

#: Hex digits of the hash kept per column (naming the column changed; the row's digest is the full SHA-256).
COLUMN_HEX = 8

STORED, FORGOTTEN, BEFORE = "stored", "forgotten", "before"


class FindingKind(StrEnum):
    """What is wrong with a stored row (:class:`Finding`)."""

    MALFORMED = "malformed"  #: a column cannot be read (a damaged blob, JSON that is not the row's)
    DIGEST = "digest"  #: the row differs from the one committed (its digest)
    NO_DIGEST = "no digest"  #: a row that was not committed by vbl-robust (no digest entry)
    DELETED = "deleted"  #: a committed row is missing from the store
    CHAIN = "chain"  #: a digest entry does not follow its run's chain (the entry was changed)
    SAMPLE = "sample"  #: the row's sample is not in the samples table, or its row changed since the commit
    SUMMARY = "summary"  #: a summary field disagrees with the row's own evaluations and the campaign's settings
    OUTSIDE_BOX = "outside box"  #: θ* (``worst_x``) lies outside the row's box


@dataclass(frozen=True)
class Finding:
    """One thing wrong with the stored row ``key``: its ``kind``, the ``fields`` (columns) concerned where known,
    and one line saying what."""

    key: str
    kind: FindingKind
    detail: str
    fields: tuple[str, ...] = ()

    def line(self) -> str:
        return f"{self.key}: {self.kind.value}: {self.detail}"


def _canonical(v: Any) -> Any:
    if isinstance(v, bytes | bytearray | memoryview):
        return {"sha256": hashlib.sha256(bytes(v)).hexdigest()}
    if isinstance(v, float) and not math.isfinite(v):
        return {"float": repr(v)}
    return v


def _text(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode()


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def job_columns(layout: int) -> tuple[str, ...]:
    """The job columns a digest of ``layout`` (a schema version) covers, in column order."""
    return tuple(c.name for c in JOBS.columns if c.since <= layout)


def row_digest(values: Mapping[str, Any], layout: int = SCHEMA_VERSION) -> tuple[str, str]:
    """``(SHA-256, column hashes)`` of a job row's stored ``values`` (``{column: value}`` as SQLite returns them)
    over the columns of ``layout``; the column hashes are :data:`COLUMN_HEX` hex digits each, space-separated, in
    column order."""
    canon = {n: _canonical(values.get(n)) for n in job_columns(layout)}
    full = _sha(_text({"layout": layout, "columns": canon}))
    return full, " ".join(_sha(_text(v))[:COLUMN_HEX] for v in canon.values())


def sample_digest(values: Mapping[str, Any]) -> str:
    """SHA-256 of a ``samples`` row (``{column: value}``)."""
    return _sha(_text({n: _canonical(values.get(n)) for n in SAMPLES.names}))


def chain_next(prev: str | None, entry: Mapping[str, Any]) -> str:
    """The chain value of ``entry`` (a ``digests`` row's fields but ``seq`` and ``chain_sha256``) after ``prev``
    (its run's previous value, None for the first)."""
    fields_ = [entry.get(n) for n in DIGESTS.names if n not in ("seq", "chain_sha256")]
    return _sha(_text([prev, *fields_]))


def store_head(heads: Mapping[int | None, str]) -> str | None:
    """One SHA-256 over every run's head (``{run_id: head}``), in run order; None when there is none."""
    if not heads:
        return None
    return _sha(_text(sorted([[-1 if r is None else r, h] for r, h in heads.items()])))


# -- writing (inside the caller's transaction) -----------------------------------------------------------------
def _select(con: sqlite3.Connection, table: Any, where: str, args: tuple[Any, ...]) -> dict[str, Any] | None:
    row = con.execute(f"SELECT {', '.join(table.names)} FROM {table.name} WHERE {where}", args).fetchone()
    return None if row is None else dict(zip(table.names, row, strict=True))


def _append(con: sqlite3.Connection, event: str, key: str, run_id: int | None,
            values: Mapping[str, Any] | None = None, sample: Mapping[str, Any] | None = None) -> None:
    row_sha, columns = row_digest(values) if values is not None else (None, None)
    entry = {"event": event, "key": key, "run_id": run_id, "layout": SCHEMA_VERSION if values is not None else None,
             "row_sha256": row_sha, "columns": columns,
             "sample_sha256": None if sample is None else sample_digest(sample)}
    prev = con.execute("SELECT chain_sha256 FROM digests WHERE run_id IS ? ORDER BY seq DESC LIMIT 1",
                       (run_id,)).fetchone()
    entry["chain_sha256"] = chain_next(None if prev is None else prev[0], entry)
    names = DIGESTS.names[1:]
    con.execute(DIGESTS.insert(names), tuple(entry[n] for n in names))


def record_stored(con: sqlite3.Connection, rowid: int) -> None:
    """The digest entry of the job row just inserted at ``rowid``: its columns read back as stored (so the digest
    is of what SQLite holds, its type affinities applied) and its sample's row."""
    values = _select(con, JOBS, "rowid = ?", (rowid,))
    if values is None:
        raise ValueError(f"no job row at rowid {rowid}")
    sample = _select(con, SAMPLES, "sample_id = ?", (values["sample_id"],))
    _append(con, STORED, values["key"], values["run_id"], values, sample)


def record_forgotten(con: sqlite3.Connection, rows: Iterable[tuple[str, int | None]]) -> None:
    """``forgotten`` entries for the job rows ``(key, run_id)`` about to be deleted (to be run again)."""
    for key, run_id in rows:
        _append(con, FORGOTTEN, key, run_id)


def mark_before(con: sqlite3.Connection) -> int:
    """``before`` entries for the job rows without one (a store brought to schema 5: rows stored before digests were
    written, not covered); returns how many."""
    rows = con.execute("SELECT key, run_id FROM jobs WHERE key NOT IN (SELECT key FROM digests) ORDER BY rowid")
    todo = rows.fetchall()
    for key, run_id in todo:
        _append(con, BEFORE, key, run_id)
    return len(todo)


def reseal(con: sqlite3.Connection) -> None:
    """Digest every job row anew as it now stands (one new chain per run; the old entries are dropped), inside the
    caller's transaction. For a store changed on purpose (a repair, a test): every run's head changes, so a head
    recorded before (a report's provenance) no longer matches — which is the point."""
    con.execute("DELETE FROM digests")
    for (rowid,) in con.execute("SELECT rowid FROM jobs ORDER BY rowid").fetchall():
        record_stored(con, rowid)


# -- checking ----------------------------------------------------------------------------------------------------
@dataclass
class Chains:
    """What the digest entries say (:func:`read_chains`): each key's latest entry, each run's head, the entries
    that do not follow their chain (``broken``: findings), and counts."""

    latest: dict[str, Mapping[str, Any]] = field(default_factory=dict)
    heads: dict[int | None, str] = field(default_factory=dict)
    broken: list[Finding] = field(default_factory=list)
    entries: int = 0

    @property
    def head(self) -> str | None:
        """:func:`store_head` of the runs' heads."""
        return store_head(self.heads)


def read_chains(entries: Iterable[Mapping[str, Any]]) -> Chains:
    """Walk the ``digests`` rows (in ``seq`` order): recompute each entry's chain value from its run's previous
    stored one (a changed entry is found where it is, not at every entry after it)."""
    out = Chains()
    for e in entries:
        out.entries += 1
        run = e["run_id"]
        if chain_next(out.heads.get(run), e) != e["chain_sha256"]:
            out.broken.append(Finding(e["key"], FindingKind.CHAIN, f"digest entry {e['seq']} of run {run} does not "
                                      "follow its chain (the entry, or the one before it, was changed)"))
        out.heads[run] = e["chain_sha256"]
        out.latest[e["key"]] = e
    return out


def check_row(values: Mapping[str, Any], entry: Mapping[str, Any] | None,
              sample: Mapping[str, Any] | None) -> list[Finding]:
    """A stored job row (``{column: value}``) against its latest digest ``entry`` (None: it has none) and its
    sample's row (None: not stored; the consistency check reports that). A ``before`` entry: not covered, nothing
    to compare."""
    key = str(values.get("key"))
    if entry is None or entry["event"] == FORGOTTEN:
        return [Finding(key, FindingKind.NO_DIGEST, "a row with no digest: not committed by vbl-robust (inserted or "
                        "re-keyed by hand)" if entry is None else "a row deleted to be run again is back without a "
                        "digest", ("key",))]
    if entry["event"] == BEFORE:
        return []
    layout = int(entry["layout"] or SCHEMA_VERSION)
    found: list[Finding] = []
    full, columns = row_digest(values, layout)
    if full != entry["row_sha256"]:
        names = job_columns(layout)
        theirs = (entry["columns"] or "").split()
        changed = tuple(n for n, mine, old in zip(names, columns.split(), theirs, strict=False) if mine != old)
        if len(theirs) != len(names):
            changed = ()
        what = ", ".join(changed) if changed else "its columns"
        found.append(Finding(key, FindingKind.DIGEST, f"{what} changed since it was committed (its digest differs)",
                             changed))
    if sample is not None and entry["sample_sha256"] is not None and sample_digest(sample) != entry["sample_sha256"]:
        found.append(Finding(key, FindingKind.SAMPLE, f"its sample's row ({values.get('sample_id')}) changed since "
                             "the row was committed", ("sample_id",)))
    return found
