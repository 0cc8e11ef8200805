"""Vulnerability zones of a stored run: each search job's optimizer rebuilt by replaying it on its stored values.

The cells of a stored search job (:func:`zones_of_run`, :func:`job_zones`, the ``vbl-robust zones`` command)
are rebuilt by **replaying** the method (:func:`replay`): the same optimizer (method, box, options, seed, budgets
from the job row) is driven through its ask/tell loop with the stored values, looked up in evaluation order — the
objective is never called. Every asked point must equal the stored one within 1e-12 (relative to max(1, |x|)),
else :class:`ReplayError`; the replay stops when the stored points are used up (a batch cut by a time budget is
told as cut, so the method never sees it, as in the original run). Time budgets are not replayed (the stored
points end where the clock stopped the run).
The zone maths is :mod:`vbl_robust.search.zones`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..constants import EPS_SAFE_M
from ..search.bounds import check_lipschitz
from ..search.zones import ZoneMap, zones
from ..space import ParameterBox
from ..specs.kinds import JobKind
from .rebuild import search_kwargs

if TYPE_CHECKING:
    from ..search.base import Optimizer
    from ..specs.campaign import CampaignSpec
    from ..store.rows import JobRow

__all__ = ["JobZones", "ReplayError", "job_zones", "replay", "zones_of_run"]

logger = logging.getLogger(__name__)

#: Tolerance of the replay's check that an asked point is the stored one (relative to max(1, |x|)).
REPLAY_TOL = 1e-12


class ReplayError(ValueError):
    """A stored job's points are not those its method asks for when replayed (other code, other options)."""


def replay(row: JobRow, spec: CampaignSpec | None = None, *, eps_safe_m: float | None = None) -> Optimizer:
    """Rebuild the optimizer of a stored search job by replaying it on its stored values (no evaluation).

    The optimizer is built as :func:`vbl_robust.campaigns.work.run_search_job` built it — method, box, options,
    seed, ``max_evals``/``max_iters`` and the early stop at ε_safe from the :class:`JobRow` and the campaign
    ``spec`` (its ``eps_safe_m`` and ``lipschitz``; or ``eps_safe_m=``) — without a time budget, and told the
    stored values (with their failure reasons and times) batch by batch in evaluation order, until the stored
    points are used up. A batch of which only a first part is stored (cut by a time budget) is told as cut
    (:meth:`~vbl_robust.search.base.Optimizer.tell_partial`): the method never sees it, as in the original run.

    Raises :class:`ReplayError` when an asked point differs from the stored one by more than 1e-12 (relative to
    max(1, |x|)), or the method stops before the stored points are used up; ``ValueError`` for a row that holds
    no search points.
    """
    from ..search.api import make_optimizer
    from ..search.evaluations import Evaluations

    if row.kind != JobKind.SEARCH or row.box is None or row.budget is None:
        raise ValueError(f"job {row.key}: not a search job ({row.kind})")
    pts = row.points
    if pts is None:
        raise ValueError(f"job {row.key}: the row holds no evaluated points (read it with with_points=True)")
    eps = eps_safe_m if eps_safe_m is not None else (spec.settings.eps_safe_m if spec is not None else EPS_SAFE_M)
    opt = make_optimizer(row.method, row.box.box, **search_kwargs(
        row.options, row.budget, eps_safe_m=eps, lipschitz=None if spec is None else spec.settings.lipschitz, seed=row.seed))
    n, pos = len(pts), 0
    while pos < n:
        x = opt.ask()
        if len(x) == 0:
            raise ReplayError(f"job {row.key} ({row.method}): the replayed search stopped after {pos} of the {n} stored "
                              f"points ({opt.message}); the store was written by other code or options")
        k = min(len(x), n - pos)
        _check_points(row, x[:k], pts.xs[pos : pos + k], pos)
        values = Evaluations(pts.fs[pos : pos + k], tuple(pts.reasons[pos : pos + k]))
        times = None if pts.times is None else pts.times[pos : pos + k]
        if k < len(x):
            opt.tell_partial(x[:k], values, times=times, message=f"replay: a batch of {len(x)} cut after {k} points")
        else:
            opt.tell(x, values, times=times)
        pos += k
    return opt


def _check_points(row: JobRow, asked: np.ndarray, stored: np.ndarray, pos: int) -> None:
    if asked.shape != stored.shape:
        raise ReplayError(f"job {row.key} ({row.method}): asked points of shape {asked.shape} at evaluation {pos}, "
                          f"stored {stored.shape}")
    with np.errstate(invalid="ignore"):
        bad = np.abs(asked - stored) > REPLAY_TOL * np.maximum(1.0, np.abs(stored))
    bad |= np.isnan(stored)
    if bad.any():
        i = int(np.flatnonzero(bad.any(axis=1))[0])
        raise ReplayError(f"job {row.key} ({row.method}): evaluation {pos + i} replays as {asked[i].tolist()} but the "
                          f"store holds {stored[i].tolist()}; the store was written by other code or options")


@dataclass(frozen=True, eq=False)
class JobZones:
    """The zones of one stored job (:func:`job_zones`).

    Attributes:
        key, sample_id, sample_index, method, role, box_label: the job's identity.
        box: Θ (None for a row without one).
        zones: the :class:`ZoneMap`, or None when the job was skipped (``note`` says why).
        note: why it was skipped, or remarks (breaching points that are no cell's centre).
        outside_breaches: ``(k, d)`` evaluated points above the threshold that are no cell's centre (a batch cut by
            a time budget; GeoRobust-A's samples along a side it left uncut) — breaches the zones do not show.
    """

    key: str
    sample_id: str
    sample_index: int
    method: str
    role: str
    box_label: str | None
    box: ParameterBox | None
    zones: ZoneMap | None
    note: str = ""
    outside_breaches: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def to_dict(self, *, with_zones: bool = True) -> dict[str, Any]:
        d: dict[str, Any] = {"key": self.key, "sample_id": self.sample_id, "sample_index": self.sample_index,
                             "method": self.method, "role": self.role, "box_label": self.box_label,
                             "box": None if self.box is None else self.box.bounds(), "note": self.note}
        if self.zones is not None:
            d.update({k: v for k, v in self.zones.to_dict(with_zones=with_zones).items() if k not in ("box", "method")})
        if len(self.outside_breaches):
            d["outside_breaches"] = self.outside_breaches.tolist()
        return d


def job_zones(row: JobRow, spec: CampaignSpec | None = None, *, threshold: float | None = None,
              lipschitz: float | Sequence[float] | None = None, norm: str = "2", estimate: bool | float = False,
              ) -> JobZones:
    """The zones of a stored job: :func:`replay` it, then :func:`zones` on its cells.

    ``threshold`` defaults to the campaign's ε_safe. With neither ``lipschitz`` nor ``estimate``, the campaign's
    own Lipschitz constant is used when it had one (sound), else nothing is ruled out. Jobs that did not run a
    search (failed, implied, PnP comparisons), rows without points and methods without a cover (random, Sobol,
    APGD) come back with ``zones=None`` and a note. A :class:`ReplayError` propagates (a store that does not replay
    is an error, not a note).
    """
    from ..search.api import METHODS

    eps = threshold if threshold is not None else (spec.settings.eps_safe_m if spec is not None else EPS_SAFE_M)
    base = dict(key=row.key, sample_id=row.sample_id, sample_index=row.sample_index, method=row.method, role=row.role,
                box_label=row.box_label, box=None if row.box is None else row.box.box)
    if row.kind != JobKind.SEARCH:
        return JobZones(**base, zones=None, note=f"a {row.kind} job: no search")
    if str(row.status) != "done":
        return JobZones(**base, zones=None, note=f"job {row.status}: {row.reason or 'no search ran'}")
    cls = METHODS.get(row.method)
    if cls is None or not cls.covers:
        return JobZones(**base, zones=None, note=f"{row.method}: keeps no cover of the box (no zones)")
    if row.points is None or len(row.points) == 0:
        return JobZones(**base, zones=None, note="no evaluated points stored")
    opt = replay(row, spec, eps_safe_m=eps)
    cells = opt.cells()
    if cells is None:
        return JobZones(**base, zones=None, note="no complete batch: no cells")
    if lipschitz is None and not estimate and spec is not None and spec.settings.lipschitz is not None:
        lipschitz = spec.settings.lipschitz
    zm = zones(cells, eps, lipschitz=lipschitz, norm=norm, estimate=estimate or None)
    pts = row.points
    with np.errstate(invalid="ignore"):
        above = pts.xs[np.isfinite(pts.fs) & (pts.fs > eps)]
    outside = above[[not _is_centre(p, cells.centers) for p in above]].reshape(-1, cells.box.dim)
    note = (f"{len(outside)} breaching evaluation(s) are no cell's centre (see outside_breaches)" if len(outside)
            else "")
    return JobZones(**base, zones=zm, note=note, outside_breaches=outside)


def _is_centre(p: np.ndarray, centers: np.ndarray) -> bool:
    tol = REPLAY_TOL * np.maximum(1.0, np.abs(p))
    return bool(np.any(np.all(np.abs(centers - p) <= tol, axis=1)))


def zones_of_run(run: str | Path, *, roles: Sequence[str] | None = None, threshold: float | None = None,
                 lipschitz: float | Sequence[float] | None = None, norm: str = "2", estimate: bool | float = False,
                 ) -> list[JobZones]:
    """:func:`job_zones` of every search job of a run directory (or its ``results.sqlite``), in store order;
    ``roles`` keeps only those roles ("main", "reference", "landscape"). Rows inconsistent with their own
    evaluations or their digests are left out (:func:`vbl_robust.campaigns.verify.screen`; logged as a warning)."""
    from ..store.core import ResultStore
    from .verify import screen

    with ResultStore.open_existing(run) as store:
        spec = store.spec() if store.holds_campaign() else None
        left_out = screen(store, spec).inconsistent
        if left_out:
            logger.warning("%s: %d job row(s) inconsistent — not used (vbl-robust verify %s names them)", run,
                           len(left_out), run)
        rows = store.jobs(kind="search", with_points=True, with_trace=False)
    rows = [r for r in rows if roles is None or r.role in roles]
    for r in rows:  # a constant that fits no box of the run is refused, even where no job keeps cells to zone
        if r.box is not None:
            check_lipschitz(lipschitz, norm, r.box.box.dim, names=r.box.box.names, where=f"the run's box {r.box_label}")
    return [job_zones(r, spec, threshold=threshold, lipschitz=lipschitz, norm=norm, estimate=estimate)
            for r in rows]


# -- refinement -------------------------------------------------------------------------------------------------
