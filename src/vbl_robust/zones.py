"""Vulnerability zones: which parts of Θ a search showed to breach, which it ruled out, which it left undecided.

A search that keeps a cover of its box (the DIRECT family, the grid: :meth:`~vbl_robust.search.Optimizer.cells`)
ends with cells that tile Θ, each with the value ``f_j`` at one evaluated point and a radius ``r_j`` around it.
Each cell is a zone of one class, against the threshold ε (ε_safe = 1000 m by default):

* **breached** — ``f_j > ε``: the cell's evaluated point breaches (an observed fact, no assumption), or another
  evaluated point inside it does (a DIRECT vertex, :attr:`Cells.extra_points`);
* **ruled out** — ``f_j + L·r_j <= ε`` (raised by a 1e-12 relative rounding margin): under the Lipschitz
  constant ``L``, no point of the cell can breach;
* **undecided** — anything else, and every cell whose value is unknown (a NaN/±inf value, a grid node not
  evaluated).

``L`` is either *given* (``lipschitz=``: a scalar with a norm ``"2"``/``"inf"``/``"1"`` of real units, or one
constant per parameter, see :mod:`vbl_robust.search.bounds`): the classification is then **sound** under the
assumption that ``L`` bounds the objective's Lipschitz constant; or the method's own **estimate**
(``estimate=``: GeoRobust's K̂, the largest observed slope, in unit-cube coordinates, with GeoRobust's size measure
``r_j`` = half the longest side of the cell in the unit cube). K̂ under-estimates the true constant, so an
estimate's "ruled out" is a guess, never a certificate: :attr:`ZoneMap.basis` says which one a map is, and
:meth:`ZoneMap.describe` labels it. With neither, no cell is ruled out.

Every zone is a :class:`~vbl_robust.space.ParameterBox` in real units (so a verifier can be called on each one)
and its share of Θ's volume; the class fractions sum to 1.

From a stored run (:func:`zones_of_run`, :func:`job_zones`, the ``vbl-robust zones`` command) the cells are
rebuilt by **replaying** the method (:func:`replay`): the same optimizer (method, box, options, seed, budgets
from the job row) is driven through its ask/tell loop with the stored values, looked up in evaluation order — the
objective is never called. Every asked point must equal the stored one within 1e-12 (relative to max(1, |x|)),
else :class:`ReplayError`; the replay stops when the stored points are used up (a batch cut by a time budget is
told as cut, so the method never sees it, as in the original run). Time budgets are not replayed (the stored
points end where the clock stopped the run).

:func:`refine_zones` spends a further evaluation budget inside the undecided zones only (GeoRobust on each one's
box, largest first) and reclassifies.

>>> import numpy as np
>>> from vbl_robust.space import ParameterBox
>>> from vbl_robust.search import make_optimizer
>>> box = ParameterBox({"roll_deg": (-10, 10)})
>>> f = lambda x: 2000 - 500 * np.abs(x[:, 0] - 3)  # breaches on (1, 5); Lipschitz constant 500
>>> opt = make_optimizer("georobust", box, max_evals=60)
>>> while len(x := opt.ask()):
...     opt.tell(x, f(x))
>>> zm = zones(opt.cells(), 1000.0, lipschitz=500.0)
>>> zm.basis, round(sum(zm.fractions.values()), 12)
('sound', 1.0)
>>> all(1 < z.center[0] < 5 for z in zm.of("breached"))
True
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .constants import EPS_SAFE_M
from .search.bounds import ROUNDING, cell_radius, check_lipschitz
from .search.cells import Cells
from .space import MIN_RELATIVE_WIDTH, MIN_WIDTH, ParameterBox

if TYPE_CHECKING:  # pragma: no cover
    from .campaigns.spec import CampaignSpec
    from .campaigns.store import JobRow
    from .search.base import Optimizer

__all__ = ["BREACHED", "CLASSES", "RULED_OUT", "UNDECIDED", "JobZones", "Refinement", "ReplayError", "Zone",
           "ZoneMap", "job_zones", "plot_zones", "refine_zones", "replay", "zones", "zones_of_run"]

BREACHED, UNDECIDED, RULED_OUT = "breached", "undecided", "ruled_out"
#: The classes of a zone, in the order they are reported.
CLASSES = (BREACHED, UNDECIDED, RULED_OUT)
#: Tolerance of the replay's check that an asked point is the stored one (relative to max(1, |x|)).
REPLAY_TOL = 1e-12


@dataclass(frozen=True)
class Zone:
    """One cell of a cover, classified.

    Attributes:
        box: the zone as a :class:`ParameterBox` (real units). A cell thinner than a ParameterBox can map to the
            unit cube (about 2**-32 of its magnitude: 20+ trisections) is widened about its centre to that width,
            inside Θ — a superset, so a verifier's "safe" still covers the zone; ``lower``/``upper`` stay exact.
        cls: ``"breached"``, ``"undecided"`` or ``"ruled_out"``.
        value: the objective at ``center`` (NaN when unknown).
        bound: ``value + L·r``, the upper bound of the objective over the zone (sound for a ``"sound"`` map, an
            estimate for an ``"estimate"`` map); +inf when the value is unknown; None without any constant.
        center: the evaluated point (real units, ordered as ``box.names``).
        lower, upper: the exact bounds of the cell (real units).
        fraction: the zone's share of Θ's volume.
    """

    box: ParameterBox
    cls: str
    value: float
    bound: float | None
    center: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    fraction: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly: bounds as ``{name: [lower, upper]}``, non-finite numbers as None."""
        names = self.box.names
        return {"class": self.cls, "value": _num(self.value), "bound": _num(self.bound),
                "fraction": self.fraction,
                "bounds": {n: [lo, hi] for n, lo, hi in zip(names, self.lower, self.upper, strict=True)},
                "center": dict(zip(names, self.center, strict=True))}


@dataclass(frozen=True, eq=False)
class ZoneMap:
    """The zones of one cover of Θ (see the module docstring).

    Attributes:
        box: Θ.
        zones: one :class:`Zone` per cell, in the cells' order.
        threshold: ε (a zone breaches when its value is above it).
        basis: ``"sound"`` (a given Lipschitz constant), ``"estimate"`` (the method's K̂: not sound) or ``"none"``.
        lipschitz, norm: the given constant and its norm (``basis == "sound"``).
        estimate: K̂ in unit-cube coordinates (``basis == "estimate"``).
        method: the search that made the cells.
        cells: the classified :class:`~vbl_robust.search.Cells` (for :meth:`reclassify` and refinement).
    """

    box: ParameterBox
    zones: tuple[Zone, ...]
    threshold: float
    basis: str
    lipschitz: float | tuple[float, ...] | None
    norm: str | None
    estimate: float | None
    method: str
    cells: Cells

    @property
    def fractions(self) -> dict[str, float]:
        """Share of Θ's volume per class, ``{"breached", "undecided", "ruled_out"}`` (they sum to 1)."""
        out = dict.fromkeys(CLASSES, 0.0)
        for z in self.zones:
            out[z.cls] += z.fraction
        return out

    @property
    def counts(self) -> dict[str, int]:
        """Number of zones per class."""
        out = dict.fromkeys(CLASSES, 0)
        for z in self.zones:
            out[z.cls] += 1
        return out

    def of(self, cls: str) -> tuple[Zone, ...]:
        """The zones of class ``cls``."""
        if cls not in CLASSES:
            raise ValueError(f"zone class must be one of {CLASSES}, got {cls!r}")
        return tuple(z for z in self.zones if z.cls == cls)

    def describe(self) -> str:
        """One line: what the classification rests on ("sound under …" / "an estimate …")."""
        if self.basis == "sound":
            lip = (f"L = {self.lipschitz:g} ({self.norm}-norm of real units)" if not isinstance(self.lipschitz, tuple)
                   else f"L = ({', '.join(f'{v:g}' for v in self.lipschitz)}) per parameter")
            return f"sound under the assumption {lip} bounds the Lipschitz constant"
        if self.basis == "estimate":
            return (f"an estimate (K̂ = {self.estimate:g}, the largest observed slope in the unit cube; "
                    "not sound: ruled-out zones are a guess)")
        return "no Lipschitz constant: nothing is ruled out"

    def reclassify(self, *, threshold: float | None = None, lipschitz: float | Sequence[float] | None = None,
                   norm: str = "2", estimate: float | bool | None = None) -> ZoneMap:
        """The same cells under another threshold or constant (see :func:`zones`)."""
        return zones(self.cells, self.threshold if threshold is None else threshold, lipschitz=lipschitz, norm=norm,
                     estimate=estimate)

    def to_dict(self, *, with_zones: bool = True) -> dict[str, Any]:
        """JSON-friendly: box, threshold, basis (and its description), fractions, counts, zones."""
        d: dict[str, Any] = {
            "box": self.box.to_dict(), "method": self.method, "threshold": self.threshold, "basis": self.basis,
            "basis_description": self.describe(),
            "lipschitz": list(self.lipschitz) if isinstance(self.lipschitz, tuple) else self.lipschitz,
            "norm": self.norm, "estimate": self.estimate, "fractions": self.fractions, "counts": self.counts,
        }
        if with_zones:
            d["zones"] = [z.to_dict() for z in self.zones]
        return d


def zones(cells: Cells, threshold: float = EPS_SAFE_M, *, lipschitz: float | Sequence[float] | None = None,
          norm: str = "2", estimate: float | bool | None = None) -> ZoneMap:
    """Classify the cells of a cover into breached / undecided / ruled-out zones (see the module docstring).

    Args:
        cells: from :meth:`Optimizer.cells <vbl_robust.search.Optimizer.cells>` (or :func:`replay`).
        threshold: ε; a zone breaches when its value is ``> threshold``.
        lipschitz: a *given* Lipschitz constant (real units): a number (with ``norm``) or one per parameter. The
            classification is then sound under that assumption.
        norm: ``"2"``, ``"inf"`` or ``"1"`` for a scalar ``lipschitz``.
        estimate: instead, an *estimated* constant K̂ in unit-cube coordinates, or True for the method's own
            (``cells.lipschitz_estimate``); ``r`` is then half the longest side of the cell in the unit cube
            (GeoRobust's size). Not sound.

    Raises ValueError for both ``lipschitz`` and ``estimate``, a bad constant, or ``estimate=True`` when the
    cells carry no estimate.
    """
    if not isinstance(cells, Cells):
        raise ValueError(f"zones: cells must be vbl_robust.search.Cells (Optimizer.cells()), got {type(cells).__name__}")
    if isinstance(threshold, bool) or not (isinstance(threshold, int | float | np.number) and math.isfinite(threshold)):
        raise ValueError(f"zones: threshold must be a finite number, got {threshold!r}")
    threshold = float(threshold)
    estimate = None if estimate is False else estimate
    if lipschitz is not None and estimate is not None:
        raise ValueError("zones: give lipschitz (a sound constant) or estimate (the method's K̂), not both")
    box, n = cells.box, len(cells)
    known = ~cells.failed & np.isfinite(cells.values)
    radius: np.ndarray | None = None
    lip: float | tuple[float, ...] | None = None
    est: float | None = None
    if lipschitz is not None:
        lip = check_lipschitz(lipschitz, norm, box.dim)
        radius, basis = cell_radius(cells.half_widths, lip, norm), "sound"
    elif estimate is not None:
        est = cells.lipschitz_estimate if estimate is True else estimate
        if est is None:
            raise ValueError(f"zones: the {cells.method or 'method'}'s cells carry no slope estimate (estimate=True)")
        if isinstance(est, bool) or not (isinstance(est, int | float | np.number) and math.isfinite(est) and est >= 0):
            raise ValueError(f"zones: estimate must be a finite number >= 0 or True, got {estimate!r}")
        est = float(est)
        radius, basis = est * np.max(cells.half_widths_unit, axis=1), "estimate"
    else:
        basis = "none"
    values = np.where(known, cells.values, np.nan)
    bound = None if radius is None else np.where(known, values + radius, np.inf)
    cls = np.full(n, UNDECIDED, dtype=object)
    if bound is not None:
        with np.errstate(invalid="ignore"):
            margin = ROUNDING * np.maximum(1.0, np.abs(bound))
            cls[known & (bound + margin <= threshold)] = RULED_OUT
    with np.errstate(invalid="ignore"):
        cls[known & (values > threshold)] = BREACHED
        hits = cells.extra_points[cells.extra_values > threshold]
    for p in hits:  # an evaluated point that is no centre (a DIRECT vertex) breaches: so does its cell
        inside = np.all((cells.lower <= p) & (p <= cells.upper), axis=1)
        cls[inside] = BREACHED
    out = []
    for j in range(n):
        lo, hi = cells.lower[j], cells.upper[j]
        out.append(Zone(
            box=_zone_box(lo, hi, box), cls=str(cls[j]), value=float(values[j]),
            bound=None if bound is None else float(bound[j]), center=tuple(map(float, cells.centers[j])),
            lower=tuple(map(float, lo)), upper=tuple(map(float, hi)), fraction=float(cells.fractions[j]),
        ))
    return ZoneMap(box=box, zones=tuple(out), threshold=threshold, basis=basis, lipschitz=lip,
                   norm=norm if isinstance(lip, float) else None, estimate=est, method=cells.method, cells=cells)


def _zone_box(lower: np.ndarray, upper: np.ndarray, theta: ParameterBox) -> ParameterBox:
    """The cell as a ParameterBox; a cell too thin for one is widened about its centre, kept inside Θ."""
    lo, hi = np.array(lower, dtype=np.float64), np.array(upper, dtype=np.float64)
    need = 2.0 * np.maximum(MIN_RELATIVE_WIDTH * np.maximum(np.abs(lo), np.abs(hi)), MIN_WIDTH)
    thin = (hi - lo) < need
    if thin.any():
        mid = 0.5 * (lo + hi)
        lo = np.where(thin, mid - need, lo)
        hi = np.where(thin, mid + need, hi)
        shift = np.maximum(theta.lower - lo, 0.0) - np.maximum(hi - theta.upper, 0.0)
        lo, hi = np.maximum(lo + shift, theta.lower), np.minimum(hi + shift, theta.upper)
    units = dict(zip(theta.names, theta.units, strict=True))
    return ParameterBox({n: (float(a), float(b)) for n, a, b in zip(theta.names, lo, hi, strict=True)}, units=units)


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


# -- replay of a stored job -------------------------------------------------------------------------------------
class ReplayError(ValueError):
    """A stored job's points are not those its method asks for when replayed (other code, other options)."""


def replay(row: JobRow, spec: CampaignSpec | None = None, *, eps_safe_m: float | None = None) -> Optimizer:
    """Rebuild the optimizer of a stored search job by replaying it on its stored values (no evaluation).

    The optimizer is built as :func:`vbl_robust.campaigns.work.run_search_job` built it — method, box, options,
    seed, ``max_evals``/``max_iters`` and the early stop at ε_safe from the :class:`JobRow` and the campaign
    ``spec`` (its ``eps_safe_m`` and ``lipschitz``; or ``eps_safe_m=``) — without a time budget, and told the
    stored values (with their failure reasons and times) batch by batch in evaluation order, until the stored
    points are used up. A batch of which only a first part is stored (cut by a time budget) is told as cut
    (:meth:`~vbl_robust.search.Optimizer.tell_partial`): the method never sees it, as in the original run.

    Raises :class:`ReplayError` when an asked point differs from the stored one by more than 1e-12 (relative to
    max(1, |x|)), or the method stops before the stored points are used up; ``ValueError`` for a row that holds
    no search points.
    """
    from .campaigns.work import search_kwargs
    from .search import Evaluations, make_optimizer

    if row.kind != "search" or row.box is None or row.budget is None:
        raise ValueError(f"job {row.key}: not a search job ({row.kind})")
    pts = row.points
    if pts is None:
        raise ValueError(f"job {row.key}: the row holds no evaluated points (read it with with_points=True)")
    eps = eps_safe_m if eps_safe_m is not None else (spec.eps_safe_m if spec is not None else EPS_SAFE_M)
    opt = make_optimizer(row.method, row.box.box, **search_kwargs(
        row.options, row.budget, eps_safe_m=eps, lipschitz=None if spec is None else spec.lipschitz, seed=row.seed))
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
    from .search import METHODS

    eps = threshold if threshold is not None else (spec.eps_safe_m if spec is not None else EPS_SAFE_M)
    base = dict(key=row.key, sample_id=row.sample_id, sample_index=row.sample_index, method=row.method, role=row.role,
                box_label=row.box_label, box=None if row.box is None else row.box.box)
    if row.kind != "search":
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
    if lipschitz is None and not estimate and spec is not None and spec.lipschitz is not None:
        lipschitz = spec.lipschitz
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
    ``roles`` keeps only those roles ("main", "reference", "landscape")."""
    from .campaigns.spec import CampaignSpec
    from .campaigns.store import ResultStore

    with ResultStore.open_existing(run) as store:
        campaign = store.campaign()
        spec = None if campaign is None else CampaignSpec.from_dict(campaign["spec"])
        rows = store.jobs(kind="search", with_points=True, with_trace=False)
    return [job_zones(r, spec, threshold=threshold, lipschitz=lipschitz, norm=norm, estimate=estimate)
            for r in rows if roles is None or r.role in roles]


# -- refinement -------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Refinement:
    """What :func:`refine_zones` did: the zone maps before and after, the evaluations spent, the zones searched."""

    before: ZoneMap
    after: ZoneMap
    evaluations: int
    zones_refined: int
    notes: tuple[str, ...] = ()

    @property
    def changes(self) -> dict[str, float]:
        """Change of each class's volume fraction (after − before)."""
        a, b = self.after.fractions, self.before.fractions
        return {c: a[c] - b[c] for c in CLASSES}

    def to_dict(self, *, with_zones: bool = True) -> dict[str, Any]:
        return {"evaluations": self.evaluations, "zones_refined": self.zones_refined, "notes": list(self.notes),
                "before": self.before.fractions, "after": self.after.fractions, "changes": self.changes,
                "zones": self.after.to_dict(with_zones=with_zones)}


def refine_zones(objective: Callable[[np.ndarray], Any], zone_map: ZoneMap, budget: int, *,
                 method: str = "georobust", per_zone: int | None = None, seed: int = 0,
                 **options: Any) -> Refinement:
    """Spend up to ``budget`` further evaluations inside the *undecided* zones only, and reclassify.

    Each undecided zone (largest volume first) gets a search of ``method`` (a method with a cover, GeoRobust by
    default) over its exact box with ``per_zone`` evaluations (default: the budget shared evenly among the
    undecided zones, at least one division of the zone's centre: ``1 + 2d``), until the budget is spent; the zone
    is replaced by the search's cells. No early stop: the point is to classify the zone, not only to find a
    breach. The result is classified on the same basis as ``zone_map``: the same given constant, or the same
    estimate raised by the slopes the new searches observed (converted to Θ's unit cube, where a slope is at
    least as large), so zones the estimate had ruled out may come back undecided.

    ``objective``: batched, ``(n, d)`` real-unit points → ``(n,)`` values or
    :class:`~vbl_robust.search.Evaluations` (as for :func:`vbl_robust.search.maximize`).
    """
    from .search import METHODS, make_optimizer

    if not isinstance(budget, int | np.integer) or isinstance(budget, bool) or budget < 0:
        raise ValueError(f"refine_zones: budget must be an integer >= 0, got {budget!r}")
    if method not in METHODS or not METHODS[method].covers:
        raise ValueError(f"refine_zones: method must keep a cover of its box "
                         f"({', '.join(m for m, c in METHODS.items() if c.covers)}), got {method!r}")
    if per_zone is not None and (not isinstance(per_zone, int | np.integer) or isinstance(per_zone, bool) or per_zone < 1):
        raise ValueError(f"refine_zones: per_zone must be an integer >= 1 or None, got {per_zone!r}")
    theta, cells = zone_map.box, zone_map.cells
    d = theta.dim
    least = 1 + 2 * d
    undecided = sorted((j for j, z in enumerate(zone_map.zones) if z.cls == UNDECIDED),
                       key=lambda j: (-zone_map.zones[j].fraction, j))
    share = per_zone if per_zone is not None else max(least, int(budget) // max(1, len(undecided)))
    left, spent, notes = int(budget), 0, []
    pieces: dict[int, Cells] = {}
    est = zone_map.estimate
    units = dict(zip(theta.names, theta.units, strict=True))
    for j in undecided:
        if left < least:
            break
        z = zone_map.zones[j]
        try:
            sub_box = ParameterBox({n: (lo, hi) for n, lo, hi in zip(theta.names, z.lower, z.upper, strict=True)},
                                   units=units)
        except ValueError:
            notes.append(f"zone at {z.center} is too thin to search")
            continue
        opt = make_optimizer(method, sub_box, max_evals=min(share, left), seed=seed, **options)
        while len(x := opt.ask()):
            opt.tell(x, objective(x))
        left -= opt.nfev
        spent += opt.nfev
        sub = opt.cells()
        if sub is None:
            continue
        pieces[j] = sub
        if est is not None and sub.lipschitz_estimate is not None:
            est = max(est, sub.lipschitz_estimate * float(np.min(theta.width / sub_box.width)))
    merged = _merge(cells, pieces, est)
    after = zones(merged, zone_map.threshold, lipschitz=zone_map.lipschitz, norm=zone_map.norm or "2",
                  estimate=est if zone_map.basis == "estimate" else None)
    return Refinement(before=zone_map, after=after, evaluations=spent, zones_refined=len(pieces), notes=tuple(notes))


def _merge(cells: Cells, pieces: Mapping[int, Cells], estimate: float | None) -> Cells:
    """``cells`` with cell ``j`` replaced by the cells ``pieces[j]`` of a search over it (fractions of Θ)."""
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("centers", "half_widths", "lower", "upper", "values",
                                                          "failed", "fractions")}
    for j in range(len(cells)):
        src, scale, idx = (pieces[j], cells.fractions[j], slice(None)) if j in pieces else (cells, 1.0, slice(j, j + 1))
        for k in parts:
            a = getattr(src, k)[idx]
            parts[k].append(a * scale if k == "fractions" else a)
    return Cells(box=cells.box, **{k: np.concatenate(v) for k, v in parts.items()}, method=cells.method,
                 lipschitz_estimate=estimate if estimate is not None else cells.lipschitz_estimate)


# -- drawing ----------------------------------------------------------------------------------------------------
#: Colours of the classes in :func:`plot_zones`.
COLOURS = {BREACHED: "#d62728", UNDECIDED: "#bdbdbd", RULED_OUT: "#2ca02c"}


def plot_zones(zone_map: ZoneMap, path: str | Path, *, landscape: tuple[np.ndarray, np.ndarray] | None = None,
               title: str | None = None) -> Path:
    """Draw the zones of a 1-D or 2-D box to a PNG and return the path.

    1-D: the cells as coloured bands under the values at their centres, with ε (and ``landscape = (xs (n, 1),
    fs (n,))``, e.g. a dense grid, as a line). 2-D: the cells as coloured rectangles and their centres (with a
    ``landscape = (xs (n, 2), fs (n,))``: its values as a log-scale heat map under the rectangles, which are then
    drawn translucent with edges of their class's colour, and its ε contour). ValueError for more than two
    parameters or a landscape of another dimension."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import to_rgba
    from matplotlib.patches import Patch

    box = zone_map.box
    if box.dim > 2:
        raise ValueError(f"plot_zones: draws 1-D and 2-D boxes, this one has {box.dim} parameters")
    lx = lf = None
    if landscape is not None:
        lx = np.asarray(landscape[0], dtype=np.float64).reshape(len(landscape[0]), -1)
        lf = np.asarray(landscape[1], dtype=np.float64).reshape(-1)
        if lx.shape[1] != box.dim or len(lf) != len(lx):
            raise ValueError(f"plot_zones: landscape must be (xs (n, {box.dim}), fs (n,)), got xs {lx.shape}, "
                             f"fs {lf.shape}")
    fig, ax = plt.subplots(figsize=(7.0, 4.4 if box.dim == 1 else 5.6), dpi=110, layout="constrained")
    label = lambda i: f"{box.names[i]}" + (f" ({box.units[i]})" if box.units[i] else "")  # noqa: E731
    lo = np.array([z.lower for z in zone_map.zones]).reshape(-1, box.dim)
    hi = np.array([z.upper for z in zone_map.zones]).reshape(-1, box.dim)
    colour = [COLOURS[z.cls] for z in zone_map.zones]
    # one collection, not a patch per cell: thousands of cells draw in a fraction of a second
    if box.dim == 1:
        bands = np.stack([np.c_[lo[:, 0], np.zeros(len(lo))], np.c_[lo[:, 0], np.ones(len(lo))],
                          np.c_[hi[:, 0], np.ones(len(lo))], np.c_[hi[:, 0], np.zeros(len(lo))]], axis=1)
        ax.add_collection(PolyCollection(bands, facecolors=[to_rgba(c, 0.35) for c in colour], linewidths=0,
                                         transform=ax.get_xaxis_transform()), autolim=False)
        c = np.array([z.center[0] for z in zone_map.zones])
        v = np.array([z.value for z in zone_map.zones])
        order = np.argsort(c)
        if lx is not None:
            o = np.argsort(lx[:, 0])
            ax.plot(lx[o, 0], lf[o], color="0.3", lw=1, label="landscape")
        ax.plot(c[order], v[order], "k.", ms=3, label="cell centres")
        ax.axhline(zone_map.threshold, color="k", ls="--", lw=0.8, label=f"ε = {zone_map.threshold:g}")
        ax.set_xlabel(label(0))
        ax.set_ylabel("value")
        ax.set_xlim(box.lower[0], box.upper[0])
    else:
        if lx is not None:
            _heat_map(fig, ax, lx, lf, zone_map.threshold)
        rects = np.stack([lo, np.c_[lo[:, 0], hi[:, 1]], hi, np.c_[hi[:, 0], lo[:, 1]]], axis=1)
        if lx is None:
            cells = PolyCollection(rects, facecolors=[to_rgba(c, 0.8) for c in colour], edgecolors="white",
                                   linewidths=0.3)
        else:
            cells = PolyCollection(rects, facecolors=[to_rgba(c, 0.3) for c in colour], edgecolors=colour,
                                   linewidths=0.7)
        ax.add_collection(cells)
        c = np.array([z.center for z in zone_map.zones])
        ax.plot(c[:, 0], c[:, 1], "k.", ms=2)
        ax.set_xlim(box.lower[0], box.upper[0])
        ax.set_ylim(box.lower[1], box.upper[1])
        ax.set_xlabel(label(0))
        ax.set_ylabel(label(1))
    f = zone_map.fractions
    handles = [Patch(color=COLOURS[k], alpha=0.6, label=f"{k.replace('_', ' ')} {100 * f[k]:.1f} %") for k in CLASSES]
    extra = ax.get_legend_handles_labels()[0] if box.dim == 1 else []
    # below the axes, not loc="best" (its search takes seconds with thousands of cells), so it hides no cell
    fig.legend(handles=handles + extra, fontsize=7, loc="outside lower center", ncol=len(handles + extra))
    basis = {"sound": "sound under the given L", "estimate": "estimate K̂: not sound", "none": "no constant"}
    ax.set_title(title or f"{zone_map.method}: zones ({basis[zone_map.basis]})", fontsize=9)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def _heat_map(fig: Any, ax: Any, xs: np.ndarray, fs: np.ndarray, threshold: float) -> None:
    """A 2-D landscape under the zones: a log-scale heat map on its lattice (scattered points when it is none)
    and its contour at ``threshold``; non-finite and unevaluated nodes left blank, values below 1 cm at 1 cm."""
    from matplotlib.colors import LogNorm

    finite = np.isfinite(fs)
    if not finite.any():
        return
    v = np.clip(np.where(finite, fs, np.nan), 1e-2, None)
    norm = LogNorm(vmin=min(float(np.nanmin(v)), threshold / 3), vmax=max(float(np.nanmax(v)), threshold * 1.5))
    u0, u1 = np.unique(xs[:, 0]), np.unique(xs[:, 1])
    if len(u0) > 1 and len(u1) > 1 and len(u0) * len(u1) <= 2 * len(xs):  # a lattice (complete or partly evaluated)
        grid = np.full((len(u1), len(u0)), np.nan)
        grid[np.searchsorted(u1, xs[:, 1]), np.searchsorted(u0, xs[:, 0])] = v
        im = ax.pcolormesh(u0, u1, np.ma.masked_invalid(grid), shading="nearest", norm=norm, cmap="viridis")
        if np.nanmin(grid) < threshold < np.nanmax(grid):
            ax.contour(u0, u1, np.ma.masked_invalid(grid), levels=[threshold], colors="white", linewidths=1.2,
                       linestyles="--")
    else:
        im = ax.scatter(xs[finite, 0], xs[finite, 1], c=v[finite], norm=norm, cmap="viridis", s=8)
    fig.colorbar(im, ax=ax).set_label(f"landscape value (log scale; dashed: ε = {threshold:g})", fontsize=8)
