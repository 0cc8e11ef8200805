"""Sound Lipschitz upper bounds over a cover of the box.

What is sound: if the objective ``f`` satisfies ``|f(a) - f(b)| <= L * ||a - b||`` for all ``a, b`` in the box
(real units, the stated norm) and a set of cells covers the box, each cell with an exact value ``f_j`` at a point
``c_j`` and every point of the cell within distance ``r_j`` of ``c_j``, then ``max_j f_j + L * r_j`` bounds ``f``
from above on the whole box. DIRECT rectangles (value at the centre, half-widths ``h``) and a complete grid
(cells of half the spacing around each node) are such covers.

What is not sound: the DIRECT-family ``bound_estimate`` (largest *observed* slope times the size of the best
rectangle) — the observed slope under-estimates the true constant and the best rectangle is only one cell.

Norms for ``L`` (scalar): ``"2"`` (Euclidean, ``r = ||h||_2``), ``"inf"`` (``r = max h``), ``"1"``
(``r = sum h``). A per-dimension vector ``L = (L_1, ..., L_d)`` means ``|f(a) - f(b)| <= sum_i L_i |a_i - b_i|``
(units of f per unit of each parameter; ``r = sum_i L_i h_i``) — the natural form when parameters have
different units (degrees, contrast factor).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

NORMS = ("2", "inf", "1")
#: Relative outward margin of the sound bound for floating-point rounding.
ROUNDING = 1e-12


def check_lipschitz(lipschitz: float | Sequence[float] | None, norm: str, dim: int, *, names: Sequence[str] = (),
                    where: str = "the box") -> float | tuple[float, ...] | None:
    """Validate a user Lipschitz constant; returns a float, a tuple of ``dim`` floats, or None. ``names`` (the box's
    parameters) and ``where`` (e.g. a box's label) make a count that does not fit say what it should fit."""
    if lipschitz is None:
        return None
    if norm not in NORMS:
        raise ValueError(f"lipschitz_norm must be one of {NORMS}, got {norm!r}")
    arr = np.asarray(lipschitz, dtype=np.float64)
    if arr.ndim == 0:
        value = float(arr)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"lipschitz must be a finite number >= 0, got {lipschitz!r}")
        return value
    if arr.shape != (dim,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        fit = (f": {arr.size} numbers, but {where} has {dim} parameter(s) ({', '.join(names)})"
               if names and arr.shape != (dim,) else "")
        raise ValueError(f"lipschitz must be a number or {dim} finite numbers >= 0 (one per parameter), got "
                         f"{lipschitz!r}{fit}")
    return tuple(float(v) for v in arr)


def cell_radius(half_widths: np.ndarray, lipschitz: float | tuple[float, ...], norm: str) -> np.ndarray:
    """``L * r_j`` for cells with real-unit half-widths ``(n, d)``; returns ``(n,)``."""
    h = np.asarray(half_widths, dtype=np.float64)
    if isinstance(lipschitz, tuple):
        return h @ np.asarray(lipschitz)
    if norm == "2":
        r = np.sqrt(np.sum(h * h, axis=1))
    elif norm == "inf":
        r = np.max(h, axis=1)
    else:
        r = np.sum(h, axis=1)
    return lipschitz * r


def sound_upper_bound(values: np.ndarray, half_widths: np.ndarray, lipschitz: float | tuple[float, ...], norm: str) -> float:
    """``max_j values_j + L * r_j`` over a cover, raised by ``ROUNDING`` (relative) so that floating-point
    rounding of the sum cannot make it fall below the true maximum; +inf if any cell value is not finite
    (nothing is known there)."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0 or not np.all(np.isfinite(v)):
        return math.inf
    m = float(np.max(v + cell_radius(half_widths, lipschitz, norm)))
    return m + ROUNDING * max(1.0, abs(m))
