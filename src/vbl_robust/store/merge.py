"""Parts of one campaign computed elsewhere (another machine, a GPU, a cluster without a shared disk) joined into one
store: :func:`merge_runs` for run directories, ``.sqlite`` files and packed stores (``.sqlite.xz``), on top of
:func:`check_mergeable` and :func:`merge_store` for two open stores."""

from __future__ import annotations

import dataclasses
import tempfile
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..consent import refuse_without_consent
from .core import STORE, ResultStore
from .identity import check_same
from .lock import WriterLock
from .pack import restore_store
from .rows import RunRecord, RunStatus, StoredCampaign, now_iso


@dataclass(frozen=True)
class MergedSource:
    """What one source brought: ``copied`` job rows, and ``already`` rows the store held (the same keys);
    ``inconsistent`` rows not copied (they contradict their own evaluations or their digests:
    :func:`vbl_robust.campaigns.verify.check_store`)."""

    source: str
    copied: int
    already: int
    inconsistent: int = 0


@dataclass(frozen=True)
class MergeReport:
    """A merge: the store written (``into``, a ``.sqlite`` file) and each source's share, in the order given."""

    into: Path
    sources: tuple[MergedSource, ...] = ()
    #: The code versions of the runs ``into`` holds after the merge, in run order (``RunProvenance.code_version``;
    #: what the merge found, not what it did: left out of comparisons).
    code_versions: tuple[str, ...] = field(default=(), compare=False)

    @property
    def copied(self) -> int:
        return sum(s.copied for s in self.sources)

    @property
    def already(self) -> int:
        return sum(s.already for s in self.sources)


def check_mergeable(store: ResultStore, other: ResultStore, campaign: StoredCampaign | None = None, *,
                    trust: bool = False) -> StoredCampaign:
    """``ValueError`` unless ``other`` holds job rows of ``store``'s campaign and detector (or of ``campaign``, when
    given: several sources checked against the first before anything is written) on samples that agree with
    ``store``'s; returns ``other``'s campaign. A campaign whose detector names code (a factory's
    ``module:callable``, a ``.pt`` outside the package: :func:`~vbl_robust.consent.consent_needed`) is
    refused unless ``trust`` (``--trust-model``): the merged store would build it, wherever it is read next."""
    theirs = other.campaign()
    if theirs is None or other.count() == 0:
        raise ValueError(f"{other.path}: holds no job rows to merge")
    refuse_without_consent(theirs.detector or {}, trust, where=f"{other.path}: ")
    mine = campaign if campaign is not None else (store.campaign() if store.count() else None)
    if mine is not None:
        check_same(store.path, mine, theirs.stored_spec, theirs.detector,
                   hint=f"{other.path} belongs to another campaign or detector: merge only runs of one")
    here = store.samples()
    clash = [sid for sid, s in other.samples().items() if sid in here
             and (here[sid].fingerprint, here[sid].sample_index) != (s.fingerprint, s.sample_index)]
    if clash:
        raise ValueError(f"{other.path}: samples {clash[:5]} differ from {store.path}'s (another image set)")
    pixels = store.differing_pixels(other)
    if pixels:
        raise ValueError(f"{other.path}: the image files of samples {pixels[:5]} differ from those {store.path}'s "
                         "jobs read (other pixels under the same names)")
    return theirs


def merge_store(store: ResultStore, other: ResultStore, *, source: str = "", trust: bool = False,
                left_out: Callable[[ResultStore], Iterable[str]] | None = None) -> MergedSource:
    """Copy into ``store`` the job rows of ``other`` that it lacks, with their samples, image digests and runs.

    ``other`` must hold the same campaign and detector (checked as a resuming run is: ``ValueError``); a sample
    both hold must have the same fingerprint and index (:func:`check_mergeable`). ``store``, when new, is bound to
    ``other``'s campaign. Each run of ``other`` that brought rows is recorded anew (its provenance kept,
    ``config["merged_from"]`` = ``source``, default ``other``'s path), and the copied rows point to it. Rows already
    there (the same key: the same job, context and sample) are kept as they are. One transaction: all of it or
    nothing. A detector that needs consent is refused unless ``trust`` (:func:`check_mergeable`); a source whose
    stored evaluations cannot be decoded is refused (``ValueError``) before anything is written. The caller holds
    ``store``'s writer lock. ``left_out`` names the keys of ``other``'s rows not to merge (the command passes
    :func:`vbl_robust.campaigns.verify.screen`'s: rows that contradict their own evaluations or digests; the check
    lives a floor above the store)."""
    theirs = check_mergeable(store, other, trust=trust)
    label = source or str(other.path)
    try:
        stored = other.jobs(with_points=True)
    except (zlib.error, ValueError, KeyError, TypeError) as exc:  # a damaged or crafted blob: what, not where
        raise ValueError(f"{label}: a job row's stored evaluations cannot be decoded ({type(exc).__name__}: "
                         f"{exc}); nothing merged") from None
    if store.campaign() is None or store.count() == 0:
        store.bind_campaign(theirs.name, theirs.stored_spec, theirs.detector)
    have = store.done_keys()
    skipped = set(left_out(other)) if left_out is not None else set()  # e.g. rows inconsistent with themselves
    stored = [r for r in stored if r.key not in skipped]
    rows = [r for r in stored if r.key not in have]
    runs = {r.run_id: r for r in other.runs()}
    new_id: dict[int | None, int | None] = {None: None}
    with store.transaction():
        for rid in sorted({r.run_id for r in rows if r.run_id is not None}):
            run = runs.get(rid) or RunRecord(rid, now_iso(), RunStatus.UNKNOWN)
            config = {**(run.provenance.config or {}), "merged_from": label}
            new_id[rid] = store.insert_run(dataclasses.replace(
                run, provenance=dataclasses.replace(run.provenance, config=config)))
        store.insert_contents(other.contents())
        store.insert_samples(other.samples().values())  # before the rows: their digests cover their samples' rows
        store.insert_jobs(r.replace(run_id=new_id.get(r.run_id)) for r in rows)
    return MergedSource(label, len(rows), len(stored) - len(rows), len(skipped))


def store_file(run: str | Path) -> Path:
    """The store file a run names: ``run`` itself when it names a file, else ``run/results.sqlite`` (a run directory,
    existing or to be made) — what a merge writes, and how two names of one run are compared."""
    run = Path(run)
    return run / STORE if run.is_dir() or not run.suffix else run


def _unpacked(source: Path, scratch: Path) -> Path:
    """Where a source's store is read: a packed one (``….xz``) unpacked into ``scratch``, never in place."""
    if not source.name.endswith(".xz"):
        return source
    if not source.is_file():
        raise FileNotFoundError(f"{source}: no such packed store")
    restore_store(source, scratch)
    return scratch


def _check_all(dst: Path, paths: Sequence[Path], trust: bool) -> None:
    """:func:`check_mergeable` of every source, read-only, before ``dst`` is locked or created: against ``dst`` when
    it exists, else against the first source (the checks are repeated under the lock)."""
    with ResultStore.open_existing(dst if dst.is_file() else paths[0]) as mine:
        first = None
        for path in paths:
            with ResultStore.open_existing(path) as other:
                first = check_mergeable(mine, other, first, trust=trust)


def merge_runs(sources: Sequence[str | Path], into: str | Path, *, trust: bool = False,
               progress: Callable[[MergeReport], None] | None = None,
               left_out: Callable[[ResultStore], Iterable[str]] | None = None) -> MergeReport:
    """Merge the job rows of ``sources`` (run directories, ``.sqlite`` files or packed stores ``.sqlite.xz`` as
    ``bundle --stores`` writes them) into the run ``into`` (a directory or ``.sqlite`` file; created when missing)
    with :func:`merge_store`, each source recorded under the name given.

    A source whose detector names code (:func:`~vbl_robust.consent.consent_needed`) is refused unless
    ``trust`` (``--trust-model``), before ``into`` is created or touched. Every source is checked against the
    first and against ``into`` before anything is written (``ValueError``); ``into`` is refused while a run writes
    it (:class:`~vbl_robust.store.lock.WriterLock`: ``ValueError``); a missing packed store is a
    ``FileNotFoundError``, a damaged one a ``ValueError``. ``progress`` is called with the report so far after each
    source is merged (its last entry: that source); ``left_out``: as :func:`merge_store`'s."""
    dst = store_file(into)
    report = MergeReport(dst)
    with tempfile.TemporaryDirectory() as tmp:
        paths = [_unpacked(Path(src), Path(tmp) / str(i)) for i, src in enumerate(sources)]
        for src, path in zip(sources, paths, strict=True):  # consent first: nothing of into exists yet
            with ResultStore.open_existing(path) as other:
                camp = other.campaign()
                if camp is not None:
                    refuse_without_consent(camp.detector or {}, trust, where=f"{src}: ")
        _check_all(dst, paths, trust)  # a refusal leaves into as it was: not even its lock file is written
        dst.parent.mkdir(parents=True, exist_ok=True)
        with WriterLock(dst), ResultStore(dst) as store:
            first = None
            for path in paths:  # every source checked (against the first) before anything is written
                with ResultStore.open_existing(path) as other:
                    first = check_mergeable(store, other, first, trust=trust)
            for src, path in zip(sources, paths, strict=True):
                with ResultStore.open_existing(path) as other:
                    part = merge_store(store, other, source=str(src), trust=trust, left_out=left_out)
                report = dataclasses.replace(report, sources=(*report.sources, part))
                if progress is not None:
                    progress(report)
            versions = dict.fromkeys(r.provenance.code_version or "unknown" for r in store.runs())
    return dataclasses.replace(report, code_versions=tuple(versions))
