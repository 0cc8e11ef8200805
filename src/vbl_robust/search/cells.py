"""The cells of a search that keeps a cover of its box: what :meth:`Optimizer.cells` returns.

A cover is a set of cells that together tile the box, each with *one evaluated point* (its "centre") from which
every point of the cell lies within ``half_widths`` along each axis. DIRECT-family rectangles (the centre is the
evaluated point; the rectangles partition the box) and the nodes of a grid (half a spacing around each node,
clipped to the box) are covers; random, Sobol and APGD points are not (:meth:`Optimizer.cells` returns None).

Units: ``centers``, ``half_widths``, ``lower`` and ``upper`` are in real units (columns ordered as
``box.names``); ``fractions`` are exact unit-cube volumes (a DIRECT rectangle's is ``3**-sum(levels)``), so they
sum to 1 up to rounding whatever the real widths. ``half_widths`` is the *radius* of a cell along each axis: a grid
cell clipped at the box's edge keeps its node off centre, and its half-width is the distance to its far side (what
a Lipschitz bound needs), not half its clipped width.

``lipschitz_estimate`` is the method's own estimate of the objective's rate of change in **unit-cube**
coordinates (DIRECT family: the largest observed parent-child slope, GeoRobust's K̂; grid: the largest slope
between neighbouring nodes): an *estimate* that under-estimates the true constant, never a certificate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..space import ParameterBox

__all__ = ["Cells"]


@dataclass(frozen=True, eq=False)
class Cells:
    """Cells covering ``box`` (see the module docstring).

    Attributes:
        box: the search space the cells tile.
        centers: ``(m, d)`` the evaluated point of each cell, real units (bit for bit the point that was told).
        half_widths: ``(m, d)`` real units: every point ``z`` of cell ``j`` has ``|z_i - centers[j, i]| <=
            half_widths[j, i]`` (raised where needed so that this holds for the rounded ``lower``/``upper``).
        lower, upper: ``(m, d)`` the bounds of each cell, real units, inside ``box``.
        values: ``(m,)`` the value at each centre (NaN where it was not finite or not evaluated).
        failed: ``(m,)`` True where nothing is known of the cell's value (a NaN/±inf value, or a grid node not yet
            evaluated); a finite failure penalty (e.g. 5000 m) is a value, not a failed cell.
        fractions: ``(m,)`` each cell's share of the box's volume (exact unit-cube volumes).
        method: name of the method that made them.
        lipschitz_estimate: the method's slope estimate in unit-cube coordinates (None when none was observed).
        extra_points, extra_values: ``(k, d)`` / ``(k,)`` evaluated points that are no cell's centre (DIRECT's
            ``vertices=True``: the box's corners) and their values (NaN where not finite); empty by default. A
            zone map counts a cell that holds such a point above the threshold as breached (an observed fact).
    """

    box: ParameterBox
    centers: np.ndarray
    half_widths: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    values: np.ndarray
    failed: np.ndarray
    fractions: np.ndarray
    method: str = ""
    lipschitz_estimate: float | None = None
    extra_points: np.ndarray | None = None
    extra_values: np.ndarray | None = None

    def __post_init__(self) -> None:
        d = self.box.dim
        m = len(np.asarray(self.values).reshape(-1))
        xp = np.zeros((0, d)) if self.extra_points is None else np.asarray(self.extra_points, dtype=np.float64)
        xv = np.zeros(0) if self.extra_values is None else np.asarray(self.extra_values, dtype=np.float64)
        object.__setattr__(self, "extra_points", xp.reshape(-1, d))
        object.__setattr__(self, "extra_values", xv.reshape(-1))
        if len(self.extra_points) != len(self.extra_values):
            raise ValueError(f"Cells: {len(self.extra_points)} extra points but {len(self.extra_values)} extra values")
        for name in ("centers", "half_widths", "lower", "upper"):
            arr = np.asarray(getattr(self, name), dtype=np.float64).reshape(m, d)
            object.__setattr__(self, name, arr)
        # the real-unit bounds are rounded (lower + u * width): the radius covers them exactly
        radius = np.maximum(self.half_widths, np.maximum(self.centers - self.lower, self.upper - self.centers))
        object.__setattr__(self, "half_widths", radius)
        object.__setattr__(self, "values", np.asarray(self.values, dtype=np.float64).reshape(m))
        object.__setattr__(self, "failed", np.asarray(self.failed, dtype=bool).reshape(m))
        object.__setattr__(self, "fractions", np.asarray(self.fractions, dtype=np.float64).reshape(m))

    def __len__(self) -> int:
        return len(self.values)

    @property
    def half_widths_unit(self) -> np.ndarray:
        """``(m, d)`` half-widths in the box's unit cube."""
        return self.half_widths / self.box.width
