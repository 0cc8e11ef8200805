"""Rows checked against their own evaluations and their digests: what ``vbl-robust verify RUN`` runs, and what every
command that reads a store's rows for a number (``report``, ``merge``, ``bundle``, ``truth``, ``zones``) screens
them with.

A job row is *inconsistent* when

- its summary (worst value and θ*, verdict, evaluation and failure counts, failure reason at θ*) is not what its
  stored evaluations give under the campaign's settings (ε_safe, the failure penalty) — recomputed with the function
  that made it (:func:`~vbl_robust.campaigns.rebuild.result_fields` on the result its points stand for,
  :func:`~vbl_robust.campaigns.rebuild.row_result`); an implied row without the breach that implies it; a job
  not measured that holds a result;
- θ* lies outside its box;
- its sample is not in the samples table (an orphan row, or its sample row deleted: in a store that records
  samples, or where the row's digest recorded one), or the sample's row changed;
- it differs from the row committed (its digest, :mod:`~vbl_robust.store.digest`), has none, or its
  digest entry does not follow its run's chain;
- a column cannot be read.

An inconsistent row is *not used*: left out like a job not measured, counted apart ("inconsistent — not used") on
the report's first screen (:func:`banner_lines`, drawn by :mod:`vbl_robust.report.integrity`). A committed row missing from the store is a finding of the store
(no row to leave out). :func:`check_store` returns the typed findings; :func:`screen` is the check the reading
commands run (once per open store) and makes ``ResultStore.jobs`` leave the inconsistent rows out.
"""

from __future__ import annotations

import math
import weakref
from collections import Counter, defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..constants import Verdict
from ..specs.kinds import JobKind, JobStatus
from ..store.core import ResultStore
from ..store.digest import BEFORE, STORED, Finding, FindingKind, check_row, read_chains
from ..store.rows import JobRow
from ..store.schema import DIGESTS_SINCE, job_row

__all__ = ["StoreCheck", "banner_lines", "check_store", "row_findings", "screen"]

#: Relative tolerance of a recomputed value (the same floats give the same value; a margin for the last bit).
REL_TOL = 1e-9
#: Inconsistent rows listed by name on the report's first screen (all of them in ``vbl-robust verify``).
LISTED = 10


@dataclass(frozen=True)
class StoreCheck:
    """The check of a store (:func:`check_store`).

    ``rows``: job rows read; ``findings``: every finding, row by row in store order, then the store's (committed
    rows missing, digest entries that break their chain); ``inconsistent``: keys of the rows not used (a finding
    about the row itself); ``covered`` / ``before``: rows with a digest / stored before digests were written;
    ``heads``: each run's head as stored; ``head``: one digest over them."""

    rows: int
    findings: tuple[Finding, ...]
    inconsistent: frozenset[str]
    covered: int
    before: int
    heads: Mapping[int | None, str]
    head: str | None

    @property
    def ok(self) -> bool:
        return not self.findings

    @property
    def deleted(self) -> tuple[str, ...]:
        return tuple(f.key for f in self.findings if f.kind is FindingKind.DELETED)

    def by_key(self) -> dict[str, list[Finding]]:
        out: dict[str, list[Finding]] = defaultdict(list)
        for f in self.findings:
            out[f.key].append(f)
        return out

    def summary(self) -> str:
        """One line: how many rows agree with their evaluations and digests, and the head."""
        digests = (f"digests of {self.covered} row(s) in {len(self.heads)} run(s) verified, head {self.head}"
                   if self.covered else f"no digests (rows written before schema {DIGESTS_SINCE})")
        if self.before and self.covered:
            digests += f"; {self.before} row(s) written before schema {DIGESTS_SINCE} not covered"
        bad = len(self.inconsistent)
        agree = f"{self.rows - bad} of {self.rows} job rows consistent with their own evaluations"
        extra = f"; {len(self.deleted)} committed row(s) missing" if self.deleted else ""
        return f"{agree}{extra}; {digests}"


# -- one row ------------------------------------------------------------------------------------------------------
def _close(a: float | None, b: float | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return math.isclose(float(a), float(b), rel_tol=REL_TOL, abs_tol=REL_TOL)


def _same_point(a: Mapping[str, float] | None, b: Mapping[str, float] | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return set(a) == set(b) and all(_close(a[k], b[k]) for k in a)


def _risk_fields(row: JobRow, penalty_m: float, eps_safe_m: float) -> dict[str, Any]:
    """What :func:`~vbl_robust.campaigns.work.risk_row` derives from a failure-probability job's draws."""
    p = row.points
    fs = np.where(np.isfinite(p.fs), p.fs, penalty_m)
    i = int(np.argmax(fs))
    worst = float(fs[i])
    return dict(worst_m=worst, worst_x=dict(zip(row.box.box.names, map(float, p.xs[i]), strict=True)),
                verdict=Verdict.BREACH if worst > eps_safe_m else Verdict.NO_BREACH_FOUND, nfev=len(p),
                n_failed=sum(1 for r in p.reasons if r), failures=dict(sorted(Counter(r for r in p.reasons if r).items())),
                worst_reason=p.reasons[i])


def _show(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, Verdict):
        return repr(v.value)
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{k}: {_show(x)}" for k, x in v.items()) + "}"
    return repr(v)


def _outside_box(row: JobRow) -> Finding | None:
    if row.worst_x is None or row.box is None:
        return None
    box = row.box.box
    if set(row.worst_x) != set(box.names):
        return Finding(row.key, FindingKind.OUTSIDE_BOX, f"θ* names {sorted(row.worst_x)}, its box {list(box.names)}",
                       ("worst_x_json",))
    for name, lo, hi in zip(box.names, box.lower, box.upper, strict=True):
        v = row.worst_x[name]
        tol = REL_TOL * max(1.0, abs(lo), abs(hi))
        if not (isinstance(v, int | float) and math.isfinite(v) and lo - tol <= v <= hi + tol):
            return Finding(row.key, FindingKind.OUTSIDE_BOX, f"θ* {name} = {_show(v)} outside its box "
                           f"[{lo:g}, {hi:g}]", ("worst_x_json",))
    return None


#: The summary fields recomputed, and the column each is stored in.
_FIELDS = {"worst_m": "worst_m", "worst_x": "worst_x_json", "verdict": "verdict", "nfev": "nfev",
           "n_failed": "n_failed", "failures": "failures_json", "worst_reason": "worst_reason"}


def row_findings(row: JobRow, *, eps_safe_m: float, penalty_m: float, committed: bool = False) -> list[Finding]:
    """What is inconsistent in one decoded row (with its points) by itself: θ* outside its box; a job not measured
    holding a result; a search or failure-probability row whose summary is not what its stored evaluations give
    (``eps_safe_m``, ``penalty_m``: the campaign's); a searched row without its evaluations, unless ``committed``
    (its digest shows it is the row committed: rows a caller commits without points, as tests do). Implied rows
    are checked against their chain by :func:`check_store`."""
    found = [f for f in (_outside_box(row),) if f is not None]
    if row.status == JobStatus.NOT_MEASURED:
        if row.worst_m is not None or (row.points is not None and len(row.points)) or row.verdict not in (
                None, Verdict.NOT_MEASURED):
            found.append(Finding(row.key, FindingKind.SUMMARY, "a job not measured that holds a result (worst "
                                 f"{_show(row.worst_m)}, verdict {_show(row.verdict)})", ("status",)))
        return found
    if row.status == JobStatus.IMPLIED:
        if row.verdict != Verdict.BREACH or row.worst_m is None or not row.worst_m > eps_safe_m:
            found.append(Finding(row.key, FindingKind.SUMMARY, f"an implied breach of {_show(row.worst_m)} with verdict "
                                 f"{_show(row.verdict)} at ε_safe = {eps_safe_m:g} m", ("worst_m", "verdict")))
        return found
    if row.kind not in (JobKind.SEARCH, JobKind.RISK):
        return found
    if row.points is None and committed:
        return found
    if row.points is None or row.box is None:
        found.append(Finding(row.key, FindingKind.SUMMARY, "a finished job without its stored evaluations or box",
                             ("points",)))
        return found
    try:
        if row.kind == JobKind.RISK:
            expected = _risk_fields(row, penalty_m, eps_safe_m)
        else:
            from .rebuild import result_fields, row_result

            expected = result_fields(row_result(row), eps_safe_m, penalty_m)
    except (ValueError, IndexError, KeyError, TypeError) as exc:
        return [*found, Finding(row.key, FindingKind.MALFORMED, f"its evaluations do not make a result ({exc})",
                                ("points",))]
    for name, column in _FIELDS.items():
        stored, want = getattr(row, name), expected[name]
        if name in ("n_failed", "worst_reason") and stored is None:
            continue  # rows written before failures were recorded (schema < 2)
        if name == "failures" and row.n_failed is None:
            continue
        same = (_close(stored, want) if name == "worst_m" else _same_point(stored, want) if name == "worst_x"
                else dict(stored or {}) == dict(want or {}) if name == "failures" else stored == want)
        if not same:
            found.append(Finding(row.key, FindingKind.SUMMARY, f"{name} {_show(stored)} stored, its {len(row.points)} "
                                 f"evaluations give {_show(want)}", (column,)))
    return found


# -- a store ------------------------------------------------------------------------------------------------------
def _settings(store: ResultStore, spec: Any) -> tuple[float, float] | None:
    if spec is None:
        if not store.holds_campaign():
            return None
        spec = store.spec()
    return float(spec.settings.eps_safe_m), float(spec.settings.penalty_m)


def check_store(store: ResultStore, spec: Any = None) -> StoreCheck:
    """Every job row of ``store`` against its own evaluations (the settings of ``spec``, default the store's
    campaign), its box, its sample and its digest; the committed rows missing and the digest entries that break
    their chain. Reads the rows one at a time (bounded memory), all as of one moment (a store being written is
    checked as it stood); changes nothing."""
    with store.snapshot():
        return _check(store, spec)


class _Link(NamedTuple):
    """What checking an implied breach against the searched breaches of its chain needs of a row (not the row: a
    large store's breaches are many)."""

    key: str
    chain: str | None
    status: JobStatus
    box_level: float | None
    worst_m: float | None
    worst_x: Any

    @classmethod
    def of(cls, row: JobRow) -> _Link:
        return cls(row.key, row.chain, row.status, row.box_level, row.worst_m, row.worst_x)


def _check(store: ResultStore, spec: Any) -> StoreCheck:
    chains = read_chains(store.digest_entries())
    samples = store.samples()
    settings = _settings(store, spec)
    findings: list[Finding] = []
    bad: set[str] = set()
    seen: set[str] = set()
    covered = before = n = 0
    implied: list[_Link] = []
    breaches: dict[str, list[_Link]] = defaultdict(list)  # chain -> its searched breaches
    for values in store.job_columns():
        n += 1
        key = str(values["key"])
        seen.add(key)
        entry = chains.latest.get(key)
        sample = samples.get(values["sample_id"])
        row_f = check_row(values, entry, None if sample is None else sample.columns())
        if entry is not None:
            covered += entry["event"] == STORED
            before += entry["event"] == BEFORE
        # an orphan: in a store that records samples, or whose digest recorded one (rows the library commits with
        # no sample at all, as tests do, are not orphans)
        committed_with = entry is not None and entry["sample_sha256"] is not None
        if values["sample_id"] not in samples and (samples or committed_with):
            row_f.append(Finding(key, FindingKind.SAMPLE, f"its sample {values['sample_id']!r} is not in the samples "
                                 "table (an orphan row, or the sample's row deleted)", ("sample_id",)))
        try:
            row = job_row(values)
        except Exception as exc:  # any column that does not decode: the row cannot be used
            row_f.append(Finding(key, FindingKind.MALFORMED, f"a column does not read ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''})"))
            row = None
        if row is not None and settings is not None:
            committed = entry is not None and entry["event"] == STORED and not row_f
            row_f += row_findings(row, eps_safe_m=settings[0], penalty_m=settings[1], committed=committed)
            if row.status == JobStatus.IMPLIED:
                implied.append(_Link.of(row))
            elif row.chain is not None and row.verdict == Verdict.BREACH:
                breaches[row.chain].append(_Link.of(row))
        findings += row_f
        if row_f:
            bad.add(key)
    for row in implied:  # an implied breach needs its searched breach: the same chain, a smaller box, the same θ*
        src = [b for b in breaches.get(row.chain or "", ()) if b.status == JobStatus.DONE and b.key not in bad
               and (b.box_level or 0.0) < (row.box_level or 0.0) and _close(b.worst_m, row.worst_m)
               and _same_point(b.worst_x, row.worst_x)]
        if not src:
            findings.append(Finding(row.key, FindingKind.SUMMARY, f"an implied breach of {_show(row.worst_m)} with no "
                                    "consistent searched breach at a smaller box of its chain", ("worst_m", "chain")))
            bad.add(row.key)
    for key, e in chains.latest.items():
        if e["event"] == STORED and key not in seen:
            findings.append(Finding(key, FindingKind.DELETED, f"committed in run {e['run_id']}, missing from the store"))
    for f in chains.broken:
        findings.append(f)
        if f.key in seen:
            bad.add(f.key)
    if settings is None and n:
        findings.append(Finding("(campaign)", FindingKind.MALFORMED, "the store holds job rows but no campaign: its "
                                "settings are unknown, no summary could be recomputed"))
    return StoreCheck(rows=n, findings=tuple(findings), inconsistent=frozenset(bad), covered=covered, before=before,
                      heads=dict(chains.heads), head=chains.head)


_SCREENED: weakref.WeakKeyDictionary[ResultStore, tuple[tuple[int, int], StoreCheck]] = weakref.WeakKeyDictionary()


def screen(store: ResultStore, spec: Any = None) -> StoreCheck:
    """:func:`check_store` once per open store (again after it changes) and leave the inconsistent rows out of
    ``store.jobs`` from then on (``ResultStore.leave_out``). The reading commands call it before they read rows."""
    state = (store.changes, store.count())
    have = _SCREENED.get(store)
    if have is not None and have[0] == state:
        return have[1]
    check = check_store(store, spec)
    store.leave_out(check.inconsistent)
    _SCREENED[store] = (state, check)
    return check


# -- what a report shows ------------------------------------------------------------------------------------------
def _where(row_f: Sequence[Finding], rows: Mapping[str, Any]) -> str:
    key = row_f[0].key
    r = rows.get(key)
    name = key if r is None else f"{r['sample_id']} · {r['method']} · {r['box']}"
    return f"{name}: " + "; ".join(f"{f.kind.value}: {f.detail}" for f in row_f)


def banner_lines(check: StoreCheck, rows: Mapping[str, Mapping[str, Any]] | None = None) -> list[str]:
    """The first screen's words about ``check``: a head line, then up to :data:`LISTED` rows; empty when nothing
    was found. ``rows``: ``{key: {"sample_id", "method", "box"}}`` to name rows by what they are."""
    if check.ok:
        return []
    lines = []
    bad = len(check.inconsistent)
    if bad:
        lines.append(f"{bad} of {check.rows} job rows inconsistent — not used: each contradicts its own evaluations, "
                     "its box, its sample or its digest, so no number below counts it")
    if check.deleted:
        lines.append(f"{len(check.deleted)} committed job row(s) missing from the store")
    if not lines:
        lines.append("the store's digests do not follow their chain")
    per = check.by_key()
    listed = [k for k in per if k in check.inconsistent][:LISTED]
    lines += [_where(per[k], rows or {}) for k in listed]
    if bad > len(listed):
        lines.append(f"… and {bad - len(listed)} more (vbl-robust verify RUN lists them all)")
    return lines
