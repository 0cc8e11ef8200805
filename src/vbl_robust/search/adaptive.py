"""``"georobust-a"``: GeoRobust whose division follows where the objective varies (a variable metric).

Why: DIRECT divides every longest side of a potentially optimal (PO) rectangle, so its partition is isotropic in
the unit cube whatever the objective. The pipeline's error ``L(roll_deg, contrast)`` varies with roll at a scale of
0.1–0.3° and barely with contrast, and classic GeoRobust spends about half of its evaluations dividing contrast
(it then finds fewer breaches than random search in 2-D; in 1-D every DIRECT variant ties with scipy's).

The DIRECT literature, and what was taken from it:

* Jones, Perttunen & Stuckman (1993) divide along all longest sides, ranked by ``w_i`` (the best value of the
  pair) — kept: the same sampling ``c ± δ_i e_i``, the same ranking of the pairs, the same partition.
* Jones' 2001 revision (as recalled here, not re-checked) trisects along a *single* longest side, chosen by how
  often it was divided; Paulavičius & Žilinskas's DIRECT-type toolbox has the same option with the lowest index.
  Fewer evaluations per division, but the choice is still blind to ``f``: not enough here.
* Gablonsky's DIRECT-L (size = half the longest side, few ties) and GeoRobust's α-expanded PO set and one batch
  per iteration — kept unchanged (this class is a :class:`~vbl_robust.search.direct.GeoRobust`).
* Aggressive DIRECT / pDIRECT divide more rectangles per iteration for parallel machines: more evaluations per
  iteration, no better placement; not taken (filling batches up to a target size is left open).
* Sergeyev & Kvasov's diagonal DIRECT variants and BIRECT evaluate vertices / points on the main diagonal, which
  centre-sampling DIRECT never reaches (as recalled here, not re-checked) — taken in the smallest form as
  ``"georobust-av"`` (:class:`AdaptiveGeoRobustV`): the box's ``2**d`` vertices once, in the first batch, as
  ordinary evaluations (the pipeline's worst case is often the largest perturbation; measured on spatial-2d).
* What was taken: **DIRECT in a rescaled box**. DIRECT is not invariant to the scaling of the variables; with
  per-dimension Lipschitz constants ``K_i`` (the vector form of :mod:`~vbl_robust.search.bounds`) a rectangle's
  uncertainty is ``sum_i K_i h_i``, and trisecting the side with the largest ``K_i h_i`` shrinks it most. So the
  box is rescaled so that *estimated* per-dimension constants become equal, and plain GeoRobust runs in that
  metric. The estimates come from the trisection points themselves (GeoRobust's own Lipschitz estimate, per
  dimension), nothing else is evaluated.

The metric (hand-written; no library does anisotropic DIRECT with GeoRobust's PO sets and bounds):

* Slope of a division along ``i``: ``s_i = max(|f(c + δ_i e_i) - f(c)|, |f(c - δ_i e_i) - f(c)|) / δ_i``
  (unit cube, failed values skipped). Global estimate ``S_i`` = the **upper quartile** of all slopes seen along
  ``i``: a few jumps (the 5000 m failure penalty at a detection boundary) do not decide it, nor do the zero slopes
  of a flat region (a plateau of penalties, flat in every dimension) as long as a quarter of the slopes are not
  zero (measured: with the median, one of 8 instances of the 8-D barely-relevant benchmark function with a flat
  zero plateau over 30 % of its relevant coordinate was not solved in 4000 evaluations; with the upper quartile all
  were, in at most 639). Local estimate = the latest
  slope along ``i`` in the rectangle's lineage (children inherit their parent's).
* Offsets: a dimension whose estimate is at least :data:`MIN_RATIO` (27) times below the largest one counts as
  ``3**o`` times shorter, ``o = floor(log3(ratio))`` capped at ``max_offset``; ratios below 27 count as equal (a
  dead zone: on objectives that vary comparably in every dimension this *is* classic GeoRobust — the classic test
  functions measure so). The offset of a rectangle is the smaller of the global and local ones: a dimension
  counts shorter only where both agree, so a dimension that matters locally (contrast near a detection boundary)
  is divided there. A global estimate not yet known counts as offset 0; a rectangle whose local slopes are all
  zero (a flat region says nothing about the relative scales) takes the global offsets.
* Effective levels ``level_i + o_i`` (integers, so size classes stay exact integer keys, as in
  :mod:`~vbl_robust.search.direct`) decide a rectangle's size class (half its longest side in the rescaled box)
  and which sides are longest. The cap bounds the distortion, so no dimension is starved: a side that looks flat
  is *sampled* again once the other sides of its rectangle are ``3**max_offset`` times shorter; if it is still
  flat there (offset at the cap) and another side is cut with it, it is left uncut once (:data:`DEFERRALS`; it then
  counts ``3**max_offset`` times shorter again), and cut at the next look, ``3**(2 max_offset)``. Cutting it at
  the first look made the evaluations grow with the number of flat dimensions (measured on the anisotropic
  benchmark, 8-D: 1 instance of 8 not solved in 4000 evaluations and one at 2509, against all solved, at most 448);
  the look itself (2 evaluations per flat side) lets a dimension that matters only somewhere show it there.
* Split after seeing: a PO rectangle is sampled along its (effective) longest sides ``I`` as in DIRECT; the
  batch updates the metric, and the rectangle is trisected only along the sides of ``I`` that are still longest
  in the updated metric. The other samples are ordinary evaluations (best value, ``xs``/``fs``) but no
  rectangle's centre. This matters for the root, sampled along every dimension before anything is known: a flat
  dimension is not cut into slabs that would each be searched again along the others (measured on the 8-D
  anisotropic benchmark, 7 irrelevant dimensions, evaluations to 1 % of the maximum: cutting every sampled side
  gives a median of 942 and one of 8 instances unsolved in 4000, against a median of 64, all solved). The price:
  when the rectangle that kept the centre samples such a side again (or re-checks a side left uncut, above), its
  two points are evaluated again.

What stays GeoRobust: rectangles with integer levels and true bounds; α-expanded PO sets by Gablonsky's lemma;
all children of all kept PO rectangles in one batch, the same budget filter; |PO_k| and RA(k) (true volumes);
``lipschitz_estimate`` (largest observed slope, unit cube) and ``bound_estimate`` (true half longest side of the
best rectangle: an estimate); the sound ``upper_bound`` under a given constant uses every rectangle's true
half-widths (non-cubic rectangles: ``||h||_2``, ``max h``, ``sum h`` or ``sum L_i h_i``, see
:mod:`~vbl_robust.search.bounds`). The metric depends only on the values seen, never on the budget: the method
is deterministic and *anytime*. Trace rows carry the global offsets per parameter in
``extra["metric_offsets"]``.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ..space import ParameterBox
from .direct import DEPTH_CAP, GeoRobust

#: Dimensions whose slope estimates differ by less than this factor count as equally long (classic GeoRobust).
MIN_RATIO = 27.0
#: Default cap of the offsets: a side counts at most 3**5 = 243 times shorter than it is.
MAX_OFFSET = 5
#: Quantile of the slopes seen along a dimension that is its global estimate (the upper quartile).
QUANTILE = 0.75
#: How often a side at the cap is sampled and left uncut before it is cut (see the module docstring).
DEFERRALS = 1


class AdaptiveGeoRobust(GeoRobust):
    """GeoRobust in a metric rescaled by per-dimension slope estimates (see the module docstring).

    Args (besides GeoRobust's ``alpha``, ``ties``, ``eps``, ``f_scale``, ``max_depth`` and the budgets):
        max_offset: largest offset (in powers of 3) by which a less sensitive dimension counts shorter; 0 = classic
            GeoRobust (the same points).
        min_ratio: smallest ratio of slope estimates (>= 1) that gives a dimension an offset (default 27 = 3**3).
        size: only ``"side"`` (half the longest side); Jones' half-diagonal key needs cubic-ish rectangles.
    """

    name: ClassVar[str] = "georobust-a"
    label: ClassVar[str] = "GeoRobust-A (adaptive metric)"
    _arrays: ClassVar[tuple[str, ...]] = (*GeoRobust._arrays, "_local", "_deferred")
    _inherited: ClassVar[tuple[str, ...]] = ("_local", "_deferred")

    def __init__(self, box: ParameterBox, *, max_offset: int = MAX_OFFSET, min_ratio: float = MIN_RATIO,
                 **kwargs: Any):
        super().__init__(box, **kwargs)
        if self.size != "side":
            raise ValueError(f"size must be 'side' for {self.name!r} (its size classes are half the longest side of "
                             f"non-cubic rectangles), got {self.size!r}")
        if (not isinstance(max_offset, int | np.integer) or isinstance(max_offset, bool)
                or not 0 <= max_offset <= DEPTH_CAP):
            raise ValueError(f"max_offset must be an integer in [0, {DEPTH_CAP}], got {max_offset!r}")
        if isinstance(min_ratio, bool) or not (isinstance(min_ratio, int | float) and math.isfinite(min_ratio)
                                               and min_ratio >= 1):
            raise ValueError(f"min_ratio must be a finite number >= 1, got {min_ratio!r}")
        self.max_offset, self.min_ratio = int(max_offset), float(min_ratio)
        self._local = np.full((self._cap, self.dim), np.nan)  # latest slope per dimension in each lineage
        self._deferred = np.zeros((self._cap, self.dim), dtype=np.int64)
        self._slopes: list[list[float]] = [[] for _ in range(self.dim)]
        self._global_offsets = np.zeros(self.dim, dtype=np.int64)

    def _offsets(self, s: np.ndarray, unknown: int = 0) -> np.ndarray:
        """Offsets ``(n, d)`` from slope estimates ``(n, d)``, relative to each row's largest; ``unknown`` where a
        row says nothing (a NaN entry, or no positive slope in the row)."""
        known = ~np.isnan(s)
        top = np.max(np.where(known, s, -np.inf), axis=1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = top / s  # +inf for a flat dimension
            levels = np.floor(np.log(ratio) / math.log(3.0) + 1e-9)
        o = np.where(ratio >= self.min_ratio, np.minimum(levels, self.max_offset), 0.0)
        return np.where(known & (top > 0), o, unknown).astype(np.int64)

    def metric_offsets(self) -> np.ndarray:
        """The global offsets per dimension (``(d,)`` integers) at the current state."""
        return self._global_offsets.copy()

    # -- hooks of Direct ------------------------------------------------------------------------------------
    def _effective_levels(self, idx: np.ndarray) -> np.ndarray:
        # a side left uncut counts shorter again; granted once, the credit stays (measured: dropping it when the
        # side's offset falls below the cap — local slopes of a rough dimension fluctuate — cut barely relevant
        # sides again and left 2 of 8 instances of the 8-D benchmark unsolved)
        return self._levels[idx] + self._offsets_of(idx) + self.max_offset * self._deferred[idx]

    def _offsets_of(self, idx: np.ndarray) -> np.ndarray:
        local = self._offsets(self._local[idx], unknown=self.max_offset)  # no local information: the global one
        return np.minimum(local, self._global_offsets[None, :])

    def _observed(self, p: int, dims: np.ndarray, g_children: np.ndarray, failed: np.ndarray,
                  delta: np.ndarray) -> None:
        ok = ~failed
        with np.errstate(invalid="ignore"):  # a failed parent or child (inf - inf) is masked out
            slope = np.where(ok, np.abs(g_children - self._g[p]), 0.0).max(axis=1) / delta
        for i, s, seen in zip(dims.tolist(), slope.tolist(), ok.any(axis=1).tolist(), strict=True):
            if seen:
                self._local[p, i] = s
                self._slopes[i].append(s)

    def _observations_done(self) -> None:
        scale = np.array([np.quantile(s, QUANTILE) if s else np.nan for s in self._slopes])
        self._global_offsets = self._offsets(scale[None, :])[0]

    def _split_dims(self, p: int, dims: np.ndarray) -> np.ndarray:
        eff = self._effective_levels(np.array([p]))[0, dims]
        split = dims[eff == eff.min()]
        if self.max_offset > 0:
            o = self._offsets_of(np.array([p]))[0, split]
            flat = (o == self.max_offset) & (self._deferred[p, split] < DEFERRALS)
            if flat.any() and not flat.all():  # re-checked and still flat: not cut this time
                self._deferred[p, split[flat]] += 1
                split = split[~flat]
        return split

    def _tell(self, u: np.ndarray, values: np.ndarray, failed: np.ndarray, grad: np.ndarray | None) -> dict[str, Any]:
        extras = super()._tell(u, values, failed, grad)
        extras["extra"] = {"metric_offsets": self._global_offsets.tolist()}
        return extras


class AdaptiveGeoRobustV(AdaptiveGeoRobust):
    """``"georobust-av"``: :class:`AdaptiveGeoRobust` that also evaluates the box's ``2**d`` vertices in its first
    batch (``vertices=True``, up to :data:`~vbl_robust.search.direct.VERTEX_DIM_CAP` dimensions; see
    :meth:`~vbl_robust.search.direct.Direct._vertices`). The partition, PO sets, RA(k) and bounds are georobust-a's;
    only the best value and the evaluated points differ. A name of its own, so that stores written by
    ``georobust-a`` stay what they are (a resumed store never mixes the two)."""

    name: ClassVar[str] = "georobust-av"
    label: ClassVar[str] = "GeoRobust-AV (adaptive + vertices)"
    defaults: ClassVar[dict[str, Any]] = {**AdaptiveGeoRobust.defaults, "vertices": True}
