"""The SQLite results store of a campaign: one :class:`JobRow` per finished job, a :class:`RunRecord` per run,
resumable and crash-safe.

Modules, each importing only those above it:

- :mod:`.rows` — the typed rows: :class:`~.rows.StoredCampaign`, :class:`SampleRecord`, :class:`JobRow`,
  :class:`Points`, :class:`JobStatus`, :class:`RunRecord` (a :class:`RunProvenance` and how the run ended,
  :class:`RunStatus`);
- :mod:`.payloads` — what a job row's payload holds, one class per kind (:class:`~.payloads.WorstPayload`,
  :class:`~.payloads.SequencePayload`, :class:`~.payloads.RiskPayload`), each writing and reading its JSON;
- :mod:`.schema` — the tables, each declared once as columns (DDL, migrations, row ↔ columns), :data:`SCHEMA_VERSION`;
- :mod:`.identity` — what makes two runs parts of one campaign (spec, detector identity);
- :mod:`.lock` — :class:`WriterLock`, one writer per store;
- :mod:`.core` — :class:`ResultStore`: open (read-only too), migrate, campaign binding, writes and queries;
- :mod:`.pack` — packed stores (``results.sqlite.xz``): :func:`pack_store`, :func:`restore_store`;
- :mod:`.merge` — :func:`merge_runs`: parts of one campaign computed elsewhere joined into one store.
"""

from .core import PACKED, STORE, ResultStore
from .lock import WriterLock
from .merge import MergedSource, MergeReport, merge_runs, merge_store, store_file
from .pack import pack_store, restore_store
from .rows import (
    Corners,
    JobRow,
    JobStatus,
    Points,
    RunProvenance,
    RunRecord,
    RunStatus,
    SampleRecord,
    decode_points,
    encode_points,
    now_iso,
)
from .schema import JOB_COLUMNS, SCHEMA_VERSION

__all__ = [
    "JOB_COLUMNS",
    "PACKED",
    "SCHEMA_VERSION",
    "STORE",
    "Corners",
    "JobRow",
    "JobStatus",
    "MergeReport",
    "MergedSource",
    "Points",
    "ResultStore",
    "RunProvenance",
    "RunRecord",
    "RunStatus",
    "SampleRecord",
    "WriterLock",
    "decode_points",
    "encode_points",
    "merge_runs",
    "merge_store",
    "now_iso",
    "pack_store",
    "restore_store",
    "store_file",
]
