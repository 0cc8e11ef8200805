"""Vulnerability zones: which parts of Θ a search showed to breach, which it ruled out, which it left undecided.

A search that keeps a cover of its box (the DIRECT family, the grid: :meth:`~vbl_robust.search.base.Optimizer.cells`)
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

:func:`refine_zones` spends a further evaluation budget inside the undecided zones only (GeoRobust on each one's
box, largest first) and reclassifies.

>>> import numpy as np
>>> from vbl_robust.space import ParameterBox
>>> from vbl_robust.search.api import make_optimizer
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
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constants import EPS_SAFE_M
from ..space import MIN_RELATIVE_WIDTH, MIN_WIDTH, ParameterBox
from .bounds import ROUNDING, cell_radius, check_lipschitz
from .cells import Cells

__all__ = ["BREACHED", "CLASSES", "RULED_OUT", "UNDECIDED", "Refinement", "Zone", "ZoneMap", "refine_zones", "zones"]

BREACHED, UNDECIDED, RULED_OUT = "breached", "undecided", "ruled_out"
#: The classes of a zone, in the order they are reported.
CLASSES = (BREACHED, UNDECIDED, RULED_OUT)
#: Tolerance of the replay's check that an asked point is the stored one (relative to max(1, |x|)).


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
        cells: the classified :class:`~vbl_robust.search.cells.Cells` (for :meth:`reclassify` and refinement).
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
        cells: from :meth:`Optimizer.cells <vbl_robust.search.base.Optimizer.cells>` (or :func:`replay`).
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
    :class:`~vbl_robust.search.evaluations.Evaluations` (as for :func:`vbl_robust.search.maximize`).
    """
    from .api import METHODS, make_optimizer

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
