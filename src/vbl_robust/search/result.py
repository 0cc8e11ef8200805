"""The outcome of a search: :class:`SearchResult`, its per-iteration :class:`TraceRow` and the status enums.

Sense: every search *maximises*. ``fun`` is the largest finite value told, ``x`` where it was found (real
units, ordered as ``names``). An evaluation is *failed* when the objective gave it a failure reason (see
:mod:`~vbl_robust.search.evaluations`; its value, e.g. a penalty, is used by the search like any other) or its
value is NaN/±inf (kept in ``xs``/``fs`` with its raw value, counted in ``nfev``, never ``fun``). ``reasons``
holds the reason of every evaluated point (``""`` = success), ``failures`` the counts per reason.

Time stamps: ``times[i]`` is when the evaluation of ``xs[i]`` completed, in seconds on the search's clock
(started by the first ``ask``, so it covers the method's own work too); the objective is called in chunks and
every point of a chunk carries the chunk's completion time. :func:`~vbl_robust.search.anytime.at_budget` reads the
result at any smaller time or evaluation budget off these stamps.

Verdicts use the package-wide :class:`vbl_robust.constants.Verdict` (re-exported here).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict, dataclass, field, fields
from enum import Enum, StrEnum
from typing import Any

import numpy as np

from ..constants import Verdict

__all__ = ["PARTIAL", "SearchResult", "Status", "TraceRow", "verdict_for"]


class Status(StrEnum):
    """Why a search stopped (``RUNNING`` while it has not)."""

    RUNNING = "running"
    BUDGET_EXHAUSTED = "budget_exhausted"  # max_evals or max_iters reached, or the next batch does not fit
    TIME_OUT = "time_out"  # max_seconds passed (checked between batches)
    TARGET_REACHED = "target_reached"  # a finite value > stop_above was told
    CONVERGED = "converged"  # the method has nothing left to evaluate (grid done, DIRECT at max depth)
    STOPPED = "stopped"  # stopped by the caller (callback returned True, or Optimizer.stop())


#: ``TraceRow.extra`` key marking a row of a batch that was cut (by a time budget, or by reading a smaller
#: budget off a longer run): the method never saw that batch; the row counts its evaluated points.
PARTIAL = "partial"


def verdict_for(best: float, upper_bound: float | None, threshold: float) -> Verdict:
    """Answer to "can the objective exceed ``threshold`` on the box?" from the best finite value found and a
    *sound* upper bound (or None): BREACH (an evaluated point exceeds it), CERTIFIED (the bound is ≤ it), else
    NO_BREACH_FOUND."""
    if math.isfinite(best) and best > threshold:
        return Verdict.BREACH
    if upper_bound is not None and upper_bound <= threshold:
        return Verdict.CERTIFIED
    return Verdict.NO_BREACH_FOUND


@dataclass(frozen=True)
class TraceRow:
    """One iteration (= one batch = one objective call) of a search.

    ``best_value``/``best_x`` are the best so far (NaN/None before any finite value); ``n_failed`` counts the
    failed evaluations so far (a failure reason given, or a NaN/inf value). DIRECT-family fields
    (None for other methods): ``po_count_before``/``po_count_after`` = |PO_k| as selected and after the
    budget filter; ``remaining_area``/``remaining_area_after`` = RA(k) = sum of vol(p) / vol(box) over those
    two sets, computed when PO_k is selected (before division); ``lipschitz_estimate`` = largest observed
    parent-child slope (unit-cube coordinates) and ``bound_estimate`` = best + estimate x size of the best
    rectangle (an *estimate*, not sound). ``upper_bound`` is the sound bound, only when the caller supplied a
    Lipschitz constant and the method keeps a cover of the box. ``extra`` holds method-specific numbers
    (``extra["partial"] = True``: a batch cut by a time budget, see :data:`PARTIAL`). ``elapsed`` is the search's
    clock after the batch (a cut batch: when its last counted evaluation completed).
    """

    iteration: int
    nfev: int
    elapsed: float
    best_value: float
    best_x: tuple[float, ...] | None
    batch_size: int
    n_failed: int
    po_count_before: int | None = None
    po_count_after: int | None = None
    remaining_area: float | None = None
    remaining_area_after: float | None = None
    lipschitz_estimate: float | None = None
    bound_estimate: float | None = None
    upper_bound: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return _json_safe(asdict(self))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TraceRow:
        """Inverse of :meth:`to_dict` (a None ``best_value`` comes back as NaN)."""
        r = dict(d)
        r["best_value"] = math.nan if r["best_value"] is None else r["best_value"]
        r["best_x"] = None if r["best_x"] is None else tuple(r["best_x"])
        return cls(**r)


@dataclass(frozen=True, eq=False)
class SearchResult:
    """Result of a maximisation over a :class:`~vbl_robust.space.ParameterBox` (scipy-style names).

    Attributes:
        x: ``(d,)`` best point in real units, or None when no evaluation was finite.
        fun: best finite value (NaN when none).
        nfev: evaluations made (failed ones included); never more than ``max_evals``.
        nit: iterations = batches = objective calls.
        status, message: why it stopped.
        elapsed: seconds from the first ``ask`` to the last ``tell`` (a result read at a smaller budget: to the
            completion of its last counted evaluation).
        trace: one :class:`TraceRow` per iteration.
        xs, fs: ``(nfev, d)`` every evaluated point (real units) and ``(nfev,)`` its raw value.
        method, names, seed: provenance.
        n_failed: failed evaluations (a failure reason given, or a NaN/inf value).
        reasons: ``(nfev,)`` failure reason of every evaluated point, ordered as ``xs`` (``""`` = success).
        x_reason: failure reason of the evaluation at ``x`` (``""`` = success; a penalised point can be the best).
        lipschitz_estimate, bound_estimate: GeoRobust-style estimates (DIRECT family) — *not* certificates.
        upper_bound: sound upper bound of the objective over the box, valid only under the assumption that
            the objective is ``lipschitz``-Lipschitz in the ``lipschitz_norm`` of real units (None when no
            constant was given or the method keeps no cover of the box; inf when a cell had a failed value).
        times: ``(nfev,)`` completion time of each evaluation, seconds on the search's clock (see the module
            docstring); None when unknown (results stored before evaluations were stamped).
    """

    x: np.ndarray | None
    fun: float
    nfev: int
    nit: int
    status: Status
    message: str
    elapsed: float
    trace: tuple[TraceRow, ...]
    xs: np.ndarray
    fs: np.ndarray
    method: str = ""
    names: tuple[str, ...] = ()
    seed: int | None = None
    n_failed: int = 0
    reasons: tuple[str, ...] = ()
    x_reason: str = ""
    lipschitz_estimate: float | None = None
    bound_estimate: float | None = None
    upper_bound: float | None = None
    lipschitz: float | tuple[float, ...] | None = None
    lipschitz_norm: str | None = None
    times: np.ndarray | None = None

    @property
    def failures(self) -> dict[str, int]:
        """Failed evaluations per reason, ``{reason: count}`` sorted by reason (empty when none failed)."""
        return dict(sorted(Counter(r for r in self.reasons if r).items()))

    @property
    def success(self) -> bool:
        """True when at least one evaluation was finite."""
        return self.x is not None

    def x_dict(self) -> dict[str, float] | None:
        """The best point as ``{name: value}`` in real units."""
        return None if self.x is None else dict(zip(self.names, map(float, self.x), strict=True))

    def verdict(self, threshold: float) -> Verdict:
        """BREACH if some evaluated value exceeds ``threshold``; CERTIFIED if the *sound* upper bound is
        ``<= threshold``; else NO_BREACH_FOUND. The GeoRobust estimate never certifies."""
        return verdict_for(self.fun, self.upper_bound, float(threshold))

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict (lists and plain floats; non-finite floats become None)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "trace":
                v = [row.to_dict() for row in v]
            elif isinstance(v, Enum):
                v = v.value
            out[f.name] = _json_safe(v)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SearchResult:
        """Inverse of :meth:`to_dict` (None in ``fs``/``fun`` comes back as NaN)."""
        kw = dict(d)
        kw["status"] = Status(kw["status"])
        kw["x"] = None if kw["x"] is None else np.asarray(kw["x"], dtype=np.float64)
        kw["fun"] = math.nan if kw["fun"] is None else float(kw["fun"])
        names = tuple(kw.get("names", ()))
        kw["names"] = names
        kw["xs"] = np.asarray(kw["xs"], dtype=np.float64).reshape(-1, len(names) or 1)
        kw["fs"] = np.array([math.nan if v is None else v for v in kw["fs"]], dtype=np.float64)
        if isinstance(kw.get("lipschitz"), list):
            kw["lipschitz"] = tuple(kw["lipschitz"])
        kw["reasons"] = tuple(kw.get("reasons", ()))
        if kw.get("times") is not None:
            kw["times"] = np.array([math.nan if v is None else v for v in kw["times"]], dtype=np.float64)
        kw["trace"] = tuple(TraceRow.from_dict(r) for r in kw["trace"])
        return cls(**kw)


def _json_safe(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return _json_safe(v.tolist())
    if isinstance(v, dict):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_json_safe(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
