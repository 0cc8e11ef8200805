"""What a results store holds, as typed rows: the campaign it is bound to (:class:`StoredCampaign`), its samples
(:class:`SampleRecord`), a finished job (:class:`JobRow`, its evaluated :class:`Points`) and a run (:class:`RunRecord`: its :class:`RunProvenance` and how it
ended, :class:`RunStatus`). No SQL here: how each field is stored is :mod:`~vbl_robust.store.schema`'s
business.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import math
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..constants import MAX_BLOB_BYTES, NotMeasured, Verdict
from ..search.result import TraceRow
from ..specs.budget import Budget
from ..specs.campaign import BoxSpec, CampaignSpec
from ..specs.kinds import JobKind, JobStatus, Role, RunStatus


def now_iso() -> str:
    """Now, UTC, ISO 8601 to the second: the stores' timestamps."""
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class StoredCampaign:
    """The campaign a store is bound to (:meth:`~vbl_robust.store.ResultStore.campaign`).

    Attributes:
        name: the campaign's name (its spec's ``name``).
        stored_spec: the spec as stored (decoded JSON), kept as written: a store compares it and a merge binds
            another store to it (:mod:`~vbl_robust.store.identity`) without a round trip that could
            change a byte. :attr:`spec` is the same as a :class:`~vbl_robust.specs.campaign.CampaignSpec`.
        detector: the detector's identity (:meth:`~vbl_robust.campaigns.DetectorSpec.identity`).
        created_at: when the store was bound (ISO time, UTC).
    """

    name: str
    stored_spec: Mapping[str, Any]
    detector: Mapping[str, Any]
    created_at: str

    @cached_property
    def spec(self) -> CampaignSpec:
        """The campaign spec (decoded on first use: a store holding a spec of another form can still be compared,
        merged and listed)."""
        return CampaignSpec.from_dict(self.stored_spec)

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "spec", "detector", "created_at"}`` (the spec as stored): a bundle's ``provenance.json``."""
        return {"name": self.name, "spec": self.stored_spec, "detector": self.detector, "created_at": self.created_at}


@dataclass(frozen=True)
class SampleRecord:
    """One sample as a store records it (a row of the ``samples`` table; the field names are its columns, the values
    as stored: what a sample's digest covers, :func:`~vbl_robust.store.digest.sample_digest`).

    Attributes:
        sample_id: the sample's id; ``sample_index``: its place in the run's sample list.
        slant_distance_m: metres from the camera to the runway threshold.
        envelope: the approach-envelope cell it was drawn from (synthetic samples), else None.
        width, height: the image's size, pixels.
        fingerprint: what the image is (:func:`~vbl_robust.campaigns.provenance.sample_fingerprint`).
        meta_json: its plain metadata (JSON, sorted keys; :attr:`meta` decoded).
    """

    sample_id: str
    sample_index: int
    slant_distance_m: float | None = None
    envelope: str | None = None
    width: int | None = None
    height: int | None = None
    fingerprint: str | None = None
    meta_json: str | None = None

    @property
    def meta(self) -> dict[str, Any]:
        """The sample's plain metadata (``{}`` when none was stored)."""
        return json.loads(self.meta_json) if self.meta_json else {}

    def columns(self) -> dict[str, Any]:
        """``{column: value}`` as stored (what a digest of the row reads)."""
        return dataclasses.asdict(self)


#: Four predicted runway corners ``((u, v), …)`` in the sample's pixels, keypoint order TR, TL, BL, BR.
Corners = tuple[tuple[float, float], ...]


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


class StoredPoints(Points):
    """A job's points left in its read-only store until they are read (what :meth:`ResultStore.jobs` gives for
    ``with_points`` on a store read with ``points_on_demand``): ``xs``, ``fs``, ``reasons`` and ``times`` are
    decoded on each access through ``load()`` (the store's cache, bounded in bytes), so a reader holding every row
    of a large store holds none of their arrays; :meth:`to_blob` gives the stored bytes themselves
    (``load(raw=True)``). Valid while the store is open."""

    def __init__(self, load: Callable[..., Any]):  # no field of its own: nothing held
        object.__setattr__(self, "_load", load)

    xs = property(lambda self: self._load().xs)  # type: ignore[assignment]
    fs = property(lambda self: self._load().fs)  # type: ignore[assignment]
    reasons = property(lambda self: self._load().reasons)  # type: ignore[assignment]
    times = property(lambda self: self._load().times)  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"StoredPoints({len(self)} points)"

    def to_blob(self) -> bytes:
        return self._load(raw=True)


class StoredTrace(Sequence[TraceRow]):
    """A job's trace left in its store until it is read (:class:`StoredPoints`' twin for ``trace``): a sequence of
    :class:`~vbl_robust.search.result.TraceRow` decoded on each access through ``load``, equal to the tuple it
    stands for. Valid while the store is open."""

    def __init__(self, load: Callable[[], tuple[TraceRow, ...]]):
        self._load = load

    def __len__(self) -> int:
        return len(self._load())

    def __getitem__(self, i: Any) -> Any:
        return self._load()[i]

    def __iter__(self) -> Any:
        return iter(self._load())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and tuple(self._load()) == tuple(other)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return f"StoredTrace({len(self)} iterations)"


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


@dataclass(frozen=True, slots=True)
class JobRow:
    """One finished job as the store holds it (what a worker produces and ``ResultStore.jobs`` returns).

    Identity (from the :class:`~vbl_robust.specs.campaign.Job`): ``key``, ``experiment``, ``kind`` ("search" |
    "pnp"), ``role`` ("main" | "reference" | "landscape"), ``method``, ``sample_id``, ``sample_index``, ``box``,
    ``budget``, ``seed``, ``options``, ``chain``; ``run_id`` = the run that computed it.

    Outcome: ``status``; ``reason`` (why a job was not measured, ``"<NotMeasured kind>: <detail>"`` / what
    implied it); ``worst_m`` = worst error found, metres (None for a job not measured); ``worst_x`` = ``{name: value}`` of the worst point, real units;
    ``verdict`` (None for a PnP job); ``nfev``/``nit`` = evaluations / iterations; ``n_failed`` = failed
    evaluations and ``failures`` = their counts per reason (None / ``{}`` in rows stored before failures were
    recorded); ``worst_reason`` = failure reason at the worst point (``""`` = a successful evaluation, None
    unknown); ``worst_corners`` = the four corners the detector's selected candidate gave at the worst point, in the
    sample's pixels of the perturbed view (TR, TL, BL, BR; main search jobs from schema 4 on, None when no candidate
    was found, for other jobs and in older rows; its confidence is :class:`~.payloads.WorstPayload`'s);
    ``search_status``/``message`` = why the search stopped; ``search_s``/``job_s`` = seconds in the
    search / in the whole job; ``upper_bound`` (sound, metres; 1e300 for "unbounded"), ``bound_estimate``,
    ``lipschitz_estimate``; ``trace`` = the search's iterations (empty unless asked for); ``points`` = every
    evaluated point (None unless asked for); ``payload`` = the JSON as stored: a PnP comparison, or what
    :mod:`~vbl_robust.store.payloads` reads (the worst point, a sequence's facts, a risk estimate);
    ``finished_at`` (ISO time, UTC). ``read_from`` is set only on rows *derived* from a stored run at a smaller
    budget (:func:`vbl_robust.analysis.readoff.read_off_rows`; never stored): the budget label of that run.

    Floats are finite or None (SQLite stores NaN as NULL).
    """

    key: str
    experiment: str
    kind: JobKind
    role: Role
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
        object.__setattr__(self, "kind", JobKind(self.kind))
        object.__setattr__(self, "role", Role(self.role))
        object.__setattr__(self, "status", JobStatus(self.status))
        if self.verdict is not None:
            object.__setattr__(self, "verdict", Verdict(self.verdict))
        if not isinstance(self.trace, StoredTrace):
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

    @property
    def measured(self) -> bool:
        """Whether the tool completed this job (any status but ``NOT_MEASURED``): only measured rows enter a rate."""
        return self.status != JobStatus.NOT_MEASURED

    @property
    def not_measured(self) -> NotMeasured | None:
        """Why the job was not measured (:class:`~vbl_robust.constants.NotMeasured`), None for a measured row."""
        return None if self.measured else NotMeasured.of(self.reason)

    @property
    def not_measured_detail(self) -> str:
        """The reason of a job not measured without its kind (``""`` for a measured row)."""
        if self.measured:
            return ""
        head, sep, rest = (self.reason or "").partition(":")
        return rest.strip() if sep and NotMeasured.of(self.reason).value == head.strip() else (self.reason or "")

    def replace(self, **changes: Any) -> JobRow:
        """A copy with ``changes`` (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)



@dataclass(frozen=True)
class RunProvenance:
    """What one run of a campaign was, as recorded when it begins (:meth:`ResultStore.begin_run`).

    Attributes:
        code_version: the vbl-robust version (and git state) that ran it.
        model_sha256: the detector's model file SHA-256 (None for the oracle).
        detector: the detector's identity (:meth:`~vbl_robust.campaigns.DetectorSpec.identity`).
        dataset_id: SHA-256 of the dataset's identity; ``dataset`` that identity (source, image count, …).
        config: the full configuration (campaign, user options, executor, workers, clock, library versions,
            machine; ``merged_from`` on a run merged from another store).
        seed: the campaign's seed; ``executor`` / ``host``: where it ran.
        jobs_total: jobs planned; ``jobs_skipped``: of those, already stored when it began.
    """

    code_version: str | None = None
    model_sha256: str | None = None
    detector: Mapping[str, Any] | None = None
    dataset_id: str | None = None
    dataset: Mapping[str, Any] | None = None
    config: Mapping[str, Any] | None = None
    seed: int | None = None
    executor: str | None = None
    host: str | None = None
    jobs_total: int | None = None
    jobs_skipped: int | None = None


@dataclass(frozen=True)
class RunRecord:
    """One stored run: its provenance and how it ended (``ResultStore.runs``).

    ``run_id`` is None for a run not stored yet; ``started_at`` / ``finished_at`` are ISO times (UTC; no
    ``finished_at`` while running); ``jobs_done`` = jobs it stored; ``seconds`` = its wall seconds (None until it
    ends)."""

    run_id: int | None
    started_at: str
    status: RunStatus
    provenance: RunProvenance = field(default_factory=RunProvenance)
    finished_at: str | None = None
    jobs_done: int | None = None
    seconds: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", RunStatus(self.status))

    def to_dict(self) -> dict[str, Any]:
        """Its fields and its provenance's as one flat JSON-able dict (a bundle's ``provenance.json``, tables)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "provenance"}
        d["status"] = self.status.value
        return {**d, **dataclasses.asdict(self.provenance)}
