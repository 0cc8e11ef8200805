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

from .core import ResultStore
from .merge import merge_runs

__all__ = ["ResultStore", "merge_runs"]
