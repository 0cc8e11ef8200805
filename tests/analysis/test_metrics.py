import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import binomtest

from vbl_robust.analysis.breach import breach_kind, breached_images, residual_bound, survival_rate, survived
from vbl_robust.analysis.levels import distance_profile, phi_crit, smallest_breach_levels, survival_curve
from vbl_robust.analysis.metrics import convergence, pnp_summary
from vbl_robust.analysis.reference import REFERENCE_METHOD, against_reference, lattice_covered, reference_rows
from vbl_robust.analysis.summary import summarize
from vbl_robust.constants import BreachKind
from vbl_robust.search.result import TraceRow
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import roll_box
from vbl_robust.store.rows import JobRow, Points, StoredPoints


def row(**kw):
    base = {"key": "k", "experiment": "t", "kind": "search", "role": "main", "method": "georobust", "sample_id": "s",
            "sample_index": 0, "status": "done"}
    return JobRow(**{**base, **kw})


def grid_row(xs, fs, nfev, **kw):
    return row(role="reference", method="grid", box=roll_box(30), budget=Budget(max_evals=61), nfev=nfev,
               points=Points(xs, fs), **kw)


def test_survival_rate_counts_failures_as_breaches():
    assert survival_rate([10.0, 999.0, 1000.0, 1000.5, 5000.0], 1000.0) == pytest.approx(60.0)
    assert survival_rate([np.nan, 1.0], 1000.0) == 50.0
    assert math.isnan(survival_rate([], 1000.0))


def test_survived_is_the_one_survival_rule():
    eps = 1000.0
    assert survived(row(worst_m=1000.0, nfev=4), eps) and not survived(row(worst_m=1000.5, nfev=4), eps)
    assert not survived(row(worst_m=math.nan, nfev=4), eps)
    # a job the tool could not complete has no survival at all: asking for it is an error, never True or False
    with pytest.raises(ValueError, match="not measured"):
        survived(row(status="not measured", reason="tool error: boom", nfev=0), eps)
    assert survived(row(worst_m=None, nfev=0), eps)  # no evaluation within its time budget: nothing found
    rows = [row(key=f"k{i}", worst_m=w, nfev=0 if w is None else 4) for i, w in enumerate((10.0, math.inf, None, 2e3))]
    assert summarize(rows, eps)[0].survival == 50.0


def test_breach_kinds_split_flagged_failures_from_misleading_poses():
    """A flagged failure (a reason: the system knows it has no fix) is not a misleading pose (no reason, error
    above ε_safe); a job with both is misleading; the summary counts each kind and gives exact intervals."""
    eps, xs = 1000.0, np.zeros((3, 1))

    def job(i, fs, reasons, status="done"):
        fs = np.asarray(fs, dtype=np.float64)
        return row(key=f"k{i}", worst_m=float(np.nanmax(fs)), nfev=len(fs), status=status,
                   worst_reason=reasons[int(np.nanargmax(fs))], points=Points(xs, fs, reasons))

    rows = [job(0, [10, 20, 900], ("", "", "")),  # safe
            job(1, [10, 5000, 20], ("", "low_confidence", "")),  # flagged only
            job(2, [10, 5000, 3000], ("", "no_detection", "")),  # misleading below a flagged worst
            job(3, [10, 3000, 20], ("", "", "")),  # misleading worst
            job(4, [10, np.nan, 20], ("", "", ""))]  # a non-finite value: not a pose at all
    kinds = [breach_kind(r, eps) for r in rows]
    assert kinds == [BreachKind.SAFE, BreachKind.FLAGGED, BreachKind.MISLEADING, BreachKind.MISLEADING,
                     BreachKind.SAFE]
    failed = row(key="k5", worst_m=5000.0, status="failed", nfev=0)  # "failed": a store from before the name
    with pytest.raises(ValueError, match="not measured"):
        breach_kind(failed, eps)
    # without the points only a silent worst is known; a flagged worst may hide a misleading pose
    assert breach_kind(rows[3].replace(points=None), eps) is BreachKind.MISLEADING
    assert breach_kind(rows[2].replace(points=None), eps) is None
    # the job not measured is in no denominator: the group's numbers are those of the four measured rows
    s = summarize(rows[:4] + [failed], eps)[0]
    assert (s.n, s.survivors, s.flagged, s.misleading, s.not_measured) == (4, 1, 1, 2, 1)
    assert s == dataclasses.replace(summarize(rows[:4], eps)[0], not_measured=1)
    assert s.survival_rate.ci.low == pytest.approx(100 * binomtest(1, 4).proportion_ci(method="exact").low)
    line = s.as_row()
    assert (line["survival_ci_low"], line["survival_ci_high"]) == (s.survival_rate.ci.low, s.survival_rate.ci.high)
    assert (line["misleading_pct"], line["flagged_pct"]) == (50.0, 25.0)
    # a group with no row measured has no survival: NaN and no interval, never 0 % or 100 %
    alone = summarize([failed], eps)[0]
    assert (alone.n, alone.not_measured, alone.measured) == (0, 1, False) and math.isnan(alone.survival)
    assert math.isnan(alone.as_row()["survival_ci_low"]) and alone.kind_rate(BreachKind.FLAGGED) is None
    assert breached_images([failed, rows[0]], eps) == (set(), set(), False)
    unknown = summarize([rows[2].replace(points=None), rows[0]], eps)[0]
    assert unknown.misleading is None and unknown.flagged is None and math.isnan(unknown.as_row()["misleading_pct"])


def test_no_breach_in_k_uniform_points_bounds_the_breached_fraction():
    eps = 1000.0
    clean = row(method="random", worst_m=500.0, nfev=100)
    assert residual_bound(clean, eps) == pytest.approx(1 - 0.05 ** (1 / 100))
    assert residual_bound(clean.replace(worst_m=2000.0), eps) is None  # a breach: nothing residual to bound
    assert residual_bound(clean.replace(method="georobust"), eps) is None  # DIRECT's points are not uniform
    assert residual_bound(clean.replace(method="sobol"), eps) is None  # nor independent
    rows = [clean, clean.replace(key="k2", nfev=20), clean.replace(key="k3", worst_m=3000.0)]
    assert summarize(rows, eps)[0].residual == pytest.approx(1 - 0.05 ** (1 / 20))  # the weakest image's


def test_against_reference_counts_found_missed_and_beyond_the_grid():
    eps, box = 1000.0, roll_box(5)
    # grid breaks images 0-3; georobust breaks 0-2 (misses 3) and 4 (between grid nodes); 5-9 survive both
    grid = [row(key=f"g{i}", method=REFERENCE_METHOD, sample_id=f"s{i}", box=box, nfev=9,
                worst_m=3000.0 if i < 4 else 10.0) for i in range(10)]
    geo = [row(key=f"m{i}", sample_id=f"s{i}", box=box, budget=Budget(max_evals=8), nfev=8,
               worst_m=3000.0 if i in (0, 1, 2, 4) else 10.0) for i in range(10)]
    other = [row(key="o", sample_id="s99", box=box, budget=Budget(max_evals=8), nfev=8, worst_m=3000.0)]  # no grid
    (line,) = against_reference(geo + other, grid, eps)
    assert (line.method, line.box_label, line.budget_label) == ("georobust", "±5°", "8 evals")
    assert (line.n, line.grid_breaches, line.found, line.missed, line.beyond_grid) == (10, 4, 3, 1, 1)
    assert line.found_pct == 75.0 and line.p_value == 1.0
    assert against_reference(other, grid, eps) == []  # no image in common


def test_phi_crit_is_the_first_budget_below_ten_percent():
    budgets = [5, 10, 15, 20]
    # 10 images breaching at 5,5,10,10,10,10,10,10,15 and one never: survival 80, 20, 10, 10 -> never < 10
    levels = [5, 5, 10, 10, 10, 10, 10, 10, 15, math.inf]
    assert survival_curve(levels, budgets) == [80.0, 20.0, 10.0, 10.0]
    assert phi_crit(levels, budgets) == math.inf
    assert phi_crit(levels[:-1], budgets) == 15


def test_smallest_breach_levels_and_distance_profile():
    rows = []
    for sid, first in (("near", 5.0), ("mid", 15.0), ("far", math.inf), ("far2", 45.0)):
        for lv in (5.0, 15.0, 45.0):
            v = "breach" if lv >= first else "no breach found"
            rows.append(row(sample_id=sid, box=roll_box(lv), verdict=v))
    lv = smallest_breach_levels(rows)
    assert lv[("near", "georobust")] == 5 and lv[("far", "georobust")] == math.inf
    prof = distance_profile(rows, {"near": 600.0, "mid": 2000.0, "far": 5000.0, "far2": 6000.0}, [5, 15, 45])
    assert [p.quartile for p in prof] == [1, 2, 3, 4]
    assert [p.phi_crit for p in prof] == [5, 15, math.inf, 45]
    assert prof[0].d_min_m == 600.0 and prof[-1].d_max_m == 6000.0


def test_reference_rows_restrict_a_dense_grid_to_nested_boxes():
    xs = np.linspace(-30, 30, 61)[:, None]
    fs = np.where(np.abs(xs[:, 0]) > 12, 3000.0, 10.0)
    fs[30] = np.nan  # a failed evaluation counts as the penalty
    boxes = [roll_box(b) for b in (5, 10, 15, 40)]
    out = reference_rows([grid_row(xs, fs, 61)], boxes, 1000.0, 5000.0)
    assert [r.box_level for r in out] == [5, 10, 15]  # ±40 is not inside the grid
    assert [r.worst_m for r in out] == [5000.0, 5000.0, 5000.0]
    assert {r.method for r in out} == {REFERENCE_METHOD} and out[0].box == boxes[0]
    # each pseudo-row keeps the grid's points inside its box (the kind of its breach needs them)
    assert [len(r.points) for r in out] == [11, 21, 31]
    assert [breach_kind(r, 1000.0) for r in out] == [BreachKind.FLAGGED, BreachKind.FLAGGED, BreachKind.MISLEADING]
    # a grid read on demand (a large store's) is restricted on demand: the same points, none held per box
    grid = grid_row(xs, fs, 61)
    eager = grid.points
    lazy = reference_rows([grid.replace(points=StoredPoints(lambda raw=False: eager.to_blob() if raw else eager))],
                          boxes, 1000.0, 5000.0)
    assert all(isinstance(r.points, StoredPoints) for r in lazy)
    assert [r.points for r in lazy] == [r.points for r in out] and [r.worst_m for r in lazy] == [r.worst_m for r in out]
    assert [r.points.to_blob() for r in lazy] == [r.points.to_blob() for r in out]
    fs[30] = 10.0
    out = reference_rows([grid_row(xs, fs, 61)], boxes, 1000.0, 5000.0)
    assert [r.worst_m for r in out] == [10.0, 10.0, 3000.0]
    assert [r.verdict for r in out] == ["no breach found", "no breach found", "breach"]


def test_convergence_aggregates_traces():
    def trace(po, ra):
        return [TraceRow(iteration=k + 1, nfev=2 * k + 1, elapsed=0.0, best_value=1.0, best_x=None, batch_size=2,
                         n_failed=0, po_count_before=p, po_count_after=p, remaining_area=a)
                for k, (p, a) in enumerate(zip(po, ra, strict=True))]

    rows = [row(trace=trace([1, 2, 4], [1.0, 0.5, 0.2])), row(trace=trace([1, 4, 2], [1.0, 0.3, 0.1]))]
    conv = convergence(rows)
    assert [c.iteration for c in conv] == [1, 2, 3]
    assert conv[0].ra_mean == 100.0 and conv[1].po_mean == 3.0 and conv[1].po_max == 4.0 and conv[0].n == 2
    assert conv[2].ra_mean == pytest.approx(15.0) and conv[2].ra_std == pytest.approx(5.0)
    assert conv[2].ra_median == pytest.approx(15.0) and conv[2].po_after_mean == 3.0 and conv[2].nfev_mean == 5.0
    assert convergence([row(trace=[TraceRow(1, 5, 0.0, 1.0, None, 5, 0)])]) == []


def test_summarize_groups_in_first_seen_order():
    rows = [row(method=m, box=roll_box(5), budget=Budget(max_evals=10), worst_m=w, nfev=10, search_s=0.1,
                verdict="breach" if w > 1000 else "no breach found", n_failed=nf, failures=fails)
            for m, w, nf, fails in (("random", 10.0, 0, {}), ("apgd", 2000.0, None, {}),
                                    ("random", 3000.0, 3, {"no_detection": 2, "pnp_failed": 1}))]
    s = summarize(rows, 1000.0)
    assert [x.method for x in s] == ["random", "apgd"]
    assert s[0].n == 2 and s[0].survival == 50.0 and s[0].median_worst_m == 1505.0 and s[0].breaches == 1
    assert s[0].max_evals == 10 and math.isnan(s[0].max_seconds)
    assert (s[0].box_label, s[0].budget_label, s[0].nfev) == ("±5°", "10 evals", 20)
    assert s[0].failed_evals == 3 and s[0].failures == {"no_detection": 2, "pnp_failed": 1}
    assert s[1].failed_evals is None and s[1].failures == {}  # a row stored before failures were recorded
    with pytest.raises(ValueError, match="cannot group by"):
        summarize(rows, 1000.0, by=("seed",))
    assert summarize(rows, 1000.0, by=("box_label",))[0].method is None  # not grouped by method


def test_pnp_summary():
    def payload(abs_m, dist=1000.0):
        e = {"abs_m": abs_m, "rel_pct": None if abs_m is None else 100 * abs_m / dist, "reason": ""}
        return {"errors": {"ground truth": {"ippe_lm": e}}}

    rows = [row(kind="pnp", method="pnp", payload=payload(v)) for v in (10.0, 30.0, None)]
    (s,) = pnp_summary(rows)
    assert s.n == 3 and s.failures == 1 and s.median_abs_m == 20.0 and s.mae_rel_pct == 2.0


def test_reference_rows_from_a_grid_stopped_at_its_first_breach():
    # centre-out grid over ±30° (61 nodes), stopped after reaching ±13° where L first breaches
    nodes = np.linspace(-30, 30, 61)
    seen = nodes[np.argsort(np.abs(nodes), kind="stable")][:27]  # 0, ±1 … ±13
    fs = np.where(np.abs(seen) > 12, 3000.0, 10.0 + np.abs(seen))
    boxes = [roll_box(b) for b in (5, 12, 20, 30)]
    out = reference_rows([grid_row(seen[:, None], fs, 27, options={"counts": [61]})], boxes, 1000.0, 5000.0)
    assert [(r.box_level, r.worst_m, r.verdict) for r in out] == [
        (5, 15.0, "no breach found"), (12, 22.0, "no breach found"), (20, 3000.0, "breach"), (30, 3000.0, "breach")]
    # without a breach in the evaluated part, a box not fully evaluated gives no row (it would understate L)
    ref = grid_row(seen[:, None], 10.0 + np.abs(seen), 27, options={"counts": [61]})
    out = reference_rows([ref], boxes, 1000.0, 5000.0)
    assert [r.box_level for r in out] == [5, 12]
    assert lattice_covered(seen[:, None], [(-30, 30)], [61], [-13], [13])
    assert not lattice_covered(seen[:, None], [(-30, 30)], [61], [-14], [14])
