"""The truth behind "no breach found": a dense grid over a run's largest box on the images that **every** method
left surviving (``vbl-robust truth RUN``), a campaign of its own beside the run (``RUN-truth``).

In 1-D the experiments carry a dense-grid reference; in 2-D (roll × contrast) a grid over every image and box
costs too much, so nobody knew whether the images every search left surviving really survive. Those are the only
images whose true verdict is open: an image some method breached is breached (a breach is a fact). The grid runs
centre-out and stops at its first breach (so a breached image costs less than its whole lattice); an image whose
whole lattice stays below ε_safe survives up to the grid's spacing.

:func:`true_survival` then gives, at that box, the true survival (the images no method and no grid node breached)
and per method how many true breaches it missed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..specs.budget import Budget
from ..specs.campaign import Block, BoxSpec, CampaignSpec
from ..specs.kinds import JobStatus, SourceKind
from ..specs.settings import PipelineSettings
from ..store.core import ResultStore
from ..store.rows import JobRow
from .breach import budget_value, survived
from .readoff import main_rows

__all__ = ["TRUTH_SUFFIX", "TrueSurvival", "survivors_of_every_method", "true_survival", "truth_spec"]

#: The truth run of ``RUN`` is ``RUN`` + this suffix (a sibling directory); its campaign name is the run's + it.
TRUTH_SUFFIX = "-truth"
#: Grid points per objective call (centre-out; the grid stops between calls at its first breach).
BATCH = 16


def largest_box(rows: Sequence[JobRow]) -> BoxSpec:
    """The box of the largest level among ``rows`` (the main search rows of one run)."""
    boxes = [r.box for r in rows if r.box is not None]
    if not boxes:
        raise ValueError("the run holds no search rows with a box")
    return max(boxes, key=lambda b: (b.level, b.label))


def _at_largest(rows: Sequence[JobRow]) -> tuple[BoxSpec, list[JobRow]]:
    """The largest box, and the main rows there at the largest budget (a runtime run holds several budgets: its
    verdict at the largest one is the one to check)."""
    box = largest_box(rows)
    at = [r for r in rows if r.box_label == box.label]
    top = max(at, key=lambda r: (budget_value(r, "max_seconds"), budget_value(r, "max_evals")))
    return box, [r for r in at if r.budget_label == top.budget_label]


def survivors_of_every_method(store: ResultStore) -> tuple[CampaignSpec, BoxSpec, list[str], list[str]]:
    """The run's spec, its largest box, the methods, and the images every method ran at that box (at the largest
    budget) and left surviving (sorted by sample index)."""
    spec = store.spec()
    rows = [r for r in main_rows(store, spec, with_trace=False) if r.chain is None]
    box, at = _at_largest(rows)
    methods = list(dict.fromkeys(r.method for r in at))
    by: dict[str, dict[str, JobRow]] = {}
    for r in at:
        by.setdefault(r.sample_id, {})[r.method] = r
    index = {r.sample_id: r.sample_index for r in at}
    keep = [sid for sid, rs in by.items() if set(rs) == set(methods)
            and all(survived(r, spec.settings.eps_safe_m) for r in rs.values())]
    return spec, box, methods, sorted(keep, key=index.__getitem__)


def truth_spec(run_spec: CampaignSpec, box: BoxSpec, counts: Sequence[int]) -> CampaignSpec:
    """The truth campaign: a centre-out dense grid of ``counts`` points per parameter over ``box``, stopped at the
    first breach, with the run's pipeline settings (ε_safe, τ_conf, penalty, PnP, seed)."""
    if len(counts) != box.box.dim or any(int(c) < 2 for c in counts):
        raise ValueError(f"--counts: need {box.box.dim} counts >= 2 (one per parameter of {box.label}), got {counts}")
    n = math.prod(int(c) for c in counts)
    spacing = ", ".join(f"{n_}: {(hi - lo) / (int(c) - 1):.3g}" for n_, lo, hi, c in
                        zip(box.box.names, box.box.lower, box.box.upper, counts, strict=True))
    grid = {"counts": [int(c) for c in counts], "order": "center-out", "batch_size": BATCH}
    blk = Block(boxes=(box,), methods=("grid",), budgets=(Budget(max_evals=n, stop_at_breach=True),), role="reference",
                options={"grid": grid})
    s = run_spec.settings
    return CampaignSpec(run_spec.name + TRUTH_SUFFIX, (blk,), seed=run_spec.seed,
                        settings=PipelineSettings(eps_safe_m=s.eps_safe_m, penalty_m=s.penalty_m,
                                                  conf_threshold=s.conf_threshold, pnp=s.pnp),
                        figures=("landscape",), notes=(
        f"Dense grid {' × '.join(map(str, counts))} over {box.label} (spacing {spacing}), centre-out, stopped at the "
        f"first breach, on the images every method of {run_spec.name} left surviving at that box."))


@dataclass(frozen=True)
class TrueSurvival:
    """The truth at the run's largest box: ``images`` in the run, ``survivors_any`` that every method left
    surviving, ``gridded`` of those the truth grid completed, ``grid_breaches`` among them; ``true_survivors`` =
    survivors_any − grid_breaches (None until every survivor is gridded); per method the true breaches it missed
    (``missed``: images breached by another method or the grid that it left surviving)."""

    box_label: str
    counts: tuple[int, ...]
    images: int
    survivors_any: int
    gridded: int
    grid_breaches: int
    true_survivors: int | None
    missed: dict[str, int]


def true_survival(run: str | Path, truth: str | Path | None = None) -> TrueSurvival:
    """:class:`TrueSurvival` of the run directory ``run`` from its truth run (default ``RUN-truth``)."""
    run = Path(run)
    truth = Path(truth) if truth is not None else run.with_name(run.name + TRUTH_SUFFIX)
    with ResultStore.open_existing(run) as store:
        spec, box, methods, keep = survivors_of_every_method(store)
        _, rows = _at_largest([r for r in main_rows(store, spec, with_trace=False) if r.chain is None])
    with ResultStore.open_existing(truth) as tstore:
        grids = {r.sample_id: r for r in tstore.jobs(role="reference", with_trace=False)
                 if r.status == JobStatus.DONE}
        counts = tuple(tstore.spec().blocks[0].options["grid"]["counts"])
    eps = spec.settings.eps_safe_m
    done = [sid for sid in keep if sid in grids]
    hit = {sid for sid in done if not survived(grids[sid], eps)}
    ids = {r.sample_id for r in rows}
    breached = {r.sample_id for r in rows if not survived(r, eps)} | hit
    missed = {m: sum(1 for sid in breached if any(r.sample_id == sid and r.method == m and survived(r, eps)
                                                   for r in rows)) for m in methods}
    return TrueSurvival(box.label, counts, len(ids), len(keep), len(done), len(hit),
                        len(keep) - len(hit) if len(done) == len(keep) else None, missed)


def load_run_samples(store: ResultStore, ids: Sequence[str]) -> list[Any]:
    """The samples ``ids`` of a run, rebuilt from its recorded dataset source (synthetic: regenerated with the same
    count, seed and size; LARD: read again from its CSV), in the order of ``ids``."""
    from ..campaigns.samples import load_samples

    runs = store.runs()
    source = ((runs[-1].provenance.dataset if runs else None) or {}).get("source") or {}
    if source.get("kind") == SourceKind.SYNTHETIC:
        samples, _ = load_samples(int(source["n"]), int(source["seed"]), width=int(source["width"]),
                                  height=int(source["height"]))
    elif source.get("kind") == SourceKind.LARD:
        samples, _ = load_samples(int(source["n"]), int(source["seed"]), lard=Path(source["csv"]).parent)
    else:
        raise ValueError(f"{store.path}: its dataset source {source!r} cannot be rebuilt")
    by = {s.id: s for s in samples}
    missing = [sid for sid in ids if sid not in by]
    if missing:
        raise ValueError(f"{store.path}: samples {missing[:5]} are not in its rebuilt dataset")
    return [by[sid] for sid in ids]
