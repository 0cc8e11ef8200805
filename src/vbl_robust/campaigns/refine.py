"""Refine a stored run's vulnerability zones: more evaluations where its searches left Θ undecided.

What ``vbl-robust audit --refine-zones BUDGET`` does after the audit: for each main search job whose method keeps a
cover of the box (DIRECT family, grid), its zones are rebuilt from the store (:func:`vbl_robust.campaigns.replay.job_zones`,
nothing re-evaluated) and ``budget`` more evaluations are spent inside its undecided zones
(:func:`vbl_robust.search.zones.refine_zones`: GeoRobust per zone, largest first), under the given Lipschitz constant
(sound) or else each search's own estimate. The result — per job the class fractions before and after and the
refined zones — is written to ``RUN/zones_refined.json``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..atomic import atomic_write

__all__ = ["Refined", "refine_run"]


@dataclass(frozen=True)
class Refined:
    """One refined job: its image index, method and the :class:`~vbl_robust.search.zones.Refinement`."""

    sample_index: int
    method: str
    refinement: Any


def refine_run(run: str | Path, samples: list, detector: Any, budget: int, *,
               lipschitz: float | tuple[float, ...] | None) -> tuple[Path, list[Refined]]:
    """Refine the zones of every main search job of the run directory ``run`` (module docstring); ``samples`` are
    the run's samples (matched by id), ``detector`` what :func:`~vbl_robust.campaigns.work.detector_for` takes.

    Returns the path of ``zones_refined.json`` and the refined jobs. Raises :class:`~vbl_robust.campaigns.replay.ReplayError`
    when a stored search cannot be replayed, ``ValueError`` when a stored sample is not among ``samples``.
    """
    from ..campaigns.replay import ReplayError, job_zones
    from ..search.zones import refine_zones
    from ..store.core import ResultStore
    from .work import build_objective, detector_for

    with ResultStore.open_existing(run) as store:
        spec = store.spec()
        rows = store.jobs(kind="search", role="main", with_points=True, with_trace=False)
    settings = spec.settings
    by_id = {str(s.id): s for s in samples}
    det = detector_for(detector)
    entries: list[dict[str, Any]] = []
    done: list[Refined] = []
    for row in rows:
        try:
            jz = job_zones(row, spec, lipschitz=lipschitz, estimate=lipschitz is None)
        except ReplayError:
            raise
        except ValueError as exc:  # no estimate (e.g. a search that saw only failures)
            jz, note = None, str(exc)
        else:
            note = jz.note
        if jz is None or jz.zones is None:
            entries.append({"key": row.key, "sample_id": row.sample_id, "method": row.method, "note": note})
            continue
        sample = by_id.get(str(row.sample_id))
        if sample is None:
            raise ValueError(f"sample {row.sample_id} of the store is not among this run's samples")
        objective = build_objective(sample, det, row.box.box, settings)
        ref = refine_zones(objective, jz.zones, budget, seed=row.seed or 0)
        entries.append({"key": row.key, "sample_id": row.sample_id, "sample_index": row.sample_index,
                        "method": row.method, "box_label": row.box_label, "basis": ref.after.basis,
                        "basis_description": ref.after.describe(), **ref.to_dict()})
        done.append(Refined(row.sample_index, row.method, ref))
    path = Path(run) / "zones_refined.json"
    atomic_write(path, json.dumps({"budget_per_job": budget, "jobs": entries}, indent=1, allow_nan=False) + "\n")
    return path, done
