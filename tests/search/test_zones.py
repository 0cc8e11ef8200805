"""Vulnerability zones (:mod:`vbl_robust.search.zones`) on functions whose breach set and Lipschitz constant are known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import vbl_robust as vr
from vbl_robust.campaigns.replay import ReplayError, job_zones, replay, zones_of_run
from vbl_robust.report.zone_figure import plot_zones
from vbl_robust.search.api import make_optimizer
from vbl_robust.search.cells import Cells
from vbl_robust.search.evaluations import Evaluations
from vbl_robust.search.zones import CLASSES, refine_zones, zones
from vbl_robust.space import ParameterBox
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import BoxSpec
from vbl_robust.store.rows import JobRow, Points

EPS = 1000.0
BOX1 = ParameterBox({"roll_deg": (-10.0, 10.0)})
L1 = 500.0
COVERS = ("georobust", "georobust-a", "georobust-av", "direct", "direct-l", "grid")


def tent(x):
    """2000 − 500 |roll − 3|: above ε exactly on (1, 5); Lipschitz constant 500 (deg⁻¹)."""
    return 2000.0 - L1 * np.abs(x[:, 0] - 3.0)


def in_breach_set(r):
    return (r > 1.0) & (r < 5.0)


def run(method, box, f, **kw):
    opt = make_optimizer(method, box, **kw)
    while len(x := opt.ask()):
        opt.tell(x, f(x))
    return opt


def dense(z, n=41):
    """A dense grid of points inside a zone's exact bounds."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(z.lower, z.upper, strict=True)]
    return np.stack([a.reshape(-1) for a in np.meshgrid(*axes, indexing="ij")], axis=1)


@pytest.mark.parametrize("method", COVERS)
def test_a_known_1d_breach_interval(method):
    zm = zones(run(method, BOX1, tent, max_evals=60).cells(), EPS, lipschitz=L1)
    assert zm.basis == "sound" and "sound" in zm.describe()
    fr = zm.fractions
    assert set(fr) == set(CLASSES) and math.isclose(sum(fr.values()), 1.0, abs_tol=1e-12)
    assert zm.of("breached") and fr["ruled_out"] > 0.5
    for z in zm.of("breached"):
        assert in_breach_set(z.center[0]) and z.value > EPS
        # the part of the zone the constant vouches for (within (f − ε)/L of the centre) is in the breach set
        core = (z.value - EPS) / L1
        assert in_breach_set(np.array([z.center[0] - core * 0.999, z.center[0] + core * 0.999])).all()
    for z in zm.of("ruled_out"):
        assert z.bound <= EPS and np.all(tent(dense(z)) <= EPS)
        assert not in_breach_set(dense(z)[:, 0]).any()
    # breached zones hold their centre: together they meet the true set (0.2 of Θ) up to the undecided margin
    assert abs(fr["breached"] - 0.2) <= fr["undecided"] + 0.1
    for z in zm.zones:
        assert isinstance(z.box, ParameterBox) and z.box.names == ("roll_deg",)
        assert (z.box.lower[0], z.box.upper[0]) == (z.lower[0], z.upper[0])


def test_estimate_is_labelled_and_no_constant_rules_nothing_out():
    cells = run("georobust", BOX1, tent, max_evals=60).cells()
    est = zones(cells, EPS, estimate=True)
    assert est.basis == "estimate" and est.estimate == cells.lipschitz_estimate
    assert "not sound" in est.describe() and "sound under" not in est.describe()
    # K̂ in the unit cube: the tent's slope is 500 per degree, 10000 per unit of the 20° box
    assert est.estimate == pytest.approx(500.0 * 20.0)
    none = zones(cells, EPS)
    assert none.basis == "none" and none.fractions["ruled_out"] == 0.0
    assert [z.cls == "breached" for z in none.zones] == [z.cls == "breached" for z in est.zones]
    assert all(z.bound is None for z in none.zones)
    with pytest.raises(ValueError, match="not both"):
        zones(cells, EPS, lipschitz=1.0, estimate=True)
    with pytest.raises(ValueError, match="lipschitz"):
        zones(cells, EPS, lipschitz=-1.0)
    with pytest.raises(ValueError, match="Cells"):
        zones({"values": []}, EPS)


def test_failed_and_unevaluated_cells_are_undecided():
    f = lambda x: np.where(x[:, 0] > 6.0, np.inf, tent(x))  # noqa: E731
    zm = zones(run("georobust", BOX1, f, max_evals=60).cells(), EPS, lipschitz=L1)
    unknown = [z for z in zm.zones if not math.isfinite(z.value)]
    assert unknown and all(z.cls == "undecided" and z.bound == math.inf for z in unknown)
    grid = run("grid", BOX1, tent, counts=41, stop_above=EPS, order="center-out", batch_size=4)
    zg = zones(grid.cells(), EPS, lipschitz=L1)
    assert grid.nfev < 41 and sum(1 for z in zg.zones if math.isnan(z.value)) == 41 - grid.nfev
    assert math.isclose(sum(zg.fractions.values()), 1.0, abs_tol=1e-12)


def test_a_per_parameter_constant_in_2d():
    box = ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.7, 1.4)})
    lip = (100.0, 3000.0)  # m per degree, m per unit of contrast
    f = lambda x: 1500.0 - 100.0 * np.abs(x[:, 0] - 4.0) - 3000.0 * np.abs(x[:, 1] - 1.2)  # noqa: E731
    zm = zones(run("georobust-a", box, f, max_evals=300).cells(), EPS, lipschitz=lip)
    assert zm.lipschitz == lip and zm.norm is None
    for z in zm.of("ruled_out"):
        assert np.all(f(dense(z, 9)) <= EPS)
    for z in zm.of("breached"):
        assert f(np.array([z.center]))[0] > EPS


@settings(max_examples=40, deadline=None)
@given(method=st.sampled_from(COVERS), dim=st.integers(1, 2), seed=st.integers(0, 2**16),
       evals=st.integers(5, 120), level=st.floats(-0.5, 1.5))
@example(method="georobust-av", dim=2, seed=0, evals=51, level=0.0)  # a breached cell whose centre does not breach
def test_a_sound_constant_never_rules_out_a_breach(method, dim, seed, evals, level):
    rng = np.random.default_rng(seed)
    box = ParameterBox({f"p{i}": (float(-1 - rng.random()), float(1 + 3 * rng.random())) for i in range(dim)})
    a = rng.normal(size=4)
    w = rng.normal(scale=3.0, size=(4, dim))
    phi = rng.uniform(0, 2 * np.pi, size=4)

    def f(x):
        return np.sin(x @ w.T + phi) @ a

    lip_vec = tuple(float(v) for v in np.abs(a) @ np.abs(w))  # |∂f/∂x_i| <= Σ_k |a_k w_ki|
    lip_2 = float(np.abs(a) @ np.linalg.norm(w, axis=1))
    cells = run(method, box, f, max_evals=evals).cells()
    if cells is None:
        return
    threshold = float(level * np.abs(a).sum())
    for kw in ({"lipschitz": lip_vec}, {"lipschitz": lip_2, "norm": "2"}, {"lipschitz": lip_2 * 2, "norm": "inf"}):
        zm = zones(cells, threshold, **kw)
        assert math.isclose(sum(zm.fractions.values()), 1.0, abs_tol=1e-9)
        for z in zm.of("ruled_out"):
            pts = np.vstack([dense(z, 9 if dim == 1 else 5), z.lower, z.upper,
                             rng.uniform(z.lower, z.upper, size=(20, dim))])
            assert np.all(f(pts) <= threshold + 1e-9)
        hits = cells.extra_points[cells.extra_values > threshold]  # breaching DIRECT vertices (georobust-av)
        for z in zm.of("breached"):  # a breach is an observed fact: its centre breaches, or a vertex inside it does
            assert z.value > threshold or np.any(np.all((np.array(z.lower) <= hits) & (hits <= np.array(z.upper)),
                                                        axis=1))


def test_thin_cells_become_boxes_that_contain_them():
    box = ParameterBox({"roll_deg": (-10.0, 10.0)})
    c = 10.0 - 1e-13  # a sliver at the upper edge, far thinner than a ParameterBox can be
    cells = Cells(box, centers=[[c]], half_widths=[[1e-13]], lower=[[c - 1e-13]], upper=[[10.0]], values=[0.0],
                  failed=[False], fractions=[1e-14])
    z = zones(cells, EPS).zones[0]
    assert z.box.lower[0] <= z.lower[0] and z.box.upper[0] >= z.upper[0] and z.box.upper[0] <= 10.0


def test_refining_undecided_zones_shrinks_them():
    before = zones(run("direct", BOX1, tent, max_evals=30).cells(), EPS, lipschitz=L1)
    calls = []

    def f(x):
        calls.append(len(x))
        return Evaluations(tent(x), ("",) * len(x))

    ref = refine_zones(f, before, 120)
    assert ref.evaluations == sum(calls) <= 120 and ref.zones_refined >= 1
    assert ref.after.fractions["undecided"] < before.fractions["undecided"]
    assert math.isclose(sum(ref.after.fractions.values()), 1.0, abs_tol=1e-12)
    assert math.isclose(sum(ref.changes.values()), 0.0, abs_tol=1e-12)
    # the zones that were decided stay as they were; the new ones are still right
    decided = {(z.lower, z.upper, z.cls) for z in before.zones if z.cls != "undecided"}
    assert decided <= {(z.lower, z.upper, z.cls) for z in ref.after.zones}
    for z in ref.after.of("ruled_out"):
        assert np.all(tent(dense(z)) <= EPS)
    for z in ref.after.of("breached"):
        assert in_breach_set(z.center[0])
    # the searches ran inside undecided zones only
    with pytest.raises(ValueError, match="cover"):
        refine_zones(f, before, 10, method="random")
    assert refine_zones(f, before, 0).evaluations == 0


def test_refining_on_an_estimate_keeps_the_label():
    before = zones(run("georobust", BOX1, tent, max_evals=30).cells(), EPS, estimate=True)
    ref = refine_zones(tent, before, 60)
    assert ref.after.basis == "estimate" and ref.after.estimate >= before.estimate


def _row(method, box, budget, points, *, seed=3, options=None):
    return JobRow(key=f"k-{method}", experiment="t", kind="search", role="main", method=method, sample_id="s0",
                  sample_index=0, status="done", box=BoxSpec(box, "b", 1.0), budget=budget, seed=seed,
                  options=options or {}, points=points)


def _live(method, box, f, budget, *, seed=3, options=None, cut=None):
    """Run a search as the runner would; the cells after each batch, and the points it evaluated."""
    opt = make_optimizer(method, box, max_evals=budget.max_evals, max_iters=budget.max_iters, seed=seed,
                         stop_above=EPS if budget.stop_at_breach else None, **(options or {}))
    states = []
    while len(x := opt.ask()):
        v = f(x)
        opt.tell(x, Evaluations(v, tuple("no_detection" if val >= 5000 else "" for val in v)))
        states.append((opt.nfev, opt.cells()))
    r = opt.result()
    return opt, states, Points(r.xs, r.fs, r.reasons, r.times)


def _same_cells(a, b):
    for k in ("centers", "half_widths", "lower", "upper", "fractions", "failed"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert np.array_equal(a.values, b.values, equal_nan=True) and a.lipschitz_estimate == b.lipschitz_estimate
    assert np.array_equal(a.extra_points, b.extra_points)
    assert np.array_equal(a.extra_values, b.extra_values, equal_nan=True)


def gate(x):
    """A detector that fails (5000 m) for roll > 4, small errors elsewhere."""
    return np.where(x[:, 0] > 4.0, 5000.0, 20.0 + 3.0 * np.abs(x[:, 0]) + 50.0 * (x[:, -1] - 1.0) ** 2)


@pytest.mark.parametrize("method", COVERS)
@pytest.mark.parametrize("stop", [True, False])
def test_replay_rebuilds_the_live_cells(method, stop):
    box = ParameterBox({"roll_deg": (-10.0, 10.0), "contrast": (0.8, 1.2)})
    budget = Budget(max_evals=70, stop_at_breach=stop)
    opts = {"counts": [7, 5]} if method == "grid" else {"vertices": True} if method == "georobust-a" else {}
    live, states, pts = _live(method, box, gate, budget, options=opts)
    row = _row(method, box, budget, Points.from_blob(pts.to_blob()), options=opts)  # through the store's encoding
    opt = replay(row, eps_safe_m=EPS)
    assert opt.nfev == live.nfev  # (the live run may have asked once more, to find that nothing fits)
    if live.cells() is None:  # a breach inside the first batch ends the record there: no complete batch, no cells
        assert stop and opt.cells() is None and live.result().status.value == "target_reached"
        assert job_zones(row, threshold=EPS, estimate=True).note == "no complete batch: no cells"
        return
    _same_cells(opt.cells(), live.cells())
    jz = job_zones(row, threshold=EPS, estimate=True)
    assert jz.zones.basis == "estimate" and all(z.center[0] > 4.0 for z in jz.zones.of("breached"))
    # a store cut inside a batch (a time budget) replays to the state before that batch
    if method != "grid" and not stop:  # (the grid evaluates its 35 nodes in one batch; a breach stops at once)
        n_prev, cells_prev = states[-2]
        assert n_prev + 1 < states[-1][0]
        short = Points(pts.xs[: n_prev + 1], pts.fs[: n_prev + 1], pts.reasons[: n_prev + 1])
        cut = replay(_row(method, box, budget, short, options=opts), eps_safe_m=EPS)
        assert cut.nfev == n_prev + 1 and cut.status.value == "time_out"
        _same_cells(cut.cells(), cells_prev)


def test_replay_fails_loudly_on_a_store_it_does_not_reproduce():
    budget = Budget(max_evals=40, stop_at_breach=False)
    _, _, pts = _live("georobust", BOX1, tent, budget)
    xs = pts.xs.copy()
    xs[7, 0] += 1e-9
    with pytest.raises(ReplayError, match="evaluation 7"):
        replay(_row("georobust", BOX1, budget, Points(xs, pts.fs)))
    with pytest.raises(ReplayError, match="evaluation"):
        replay(_row("georobust", BOX1, budget, pts, seed=3, options={"alpha": 1}))  # other options
    more = Points(np.vstack([pts.xs, pts.xs[:3]]), np.r_[pts.fs, pts.fs[:3]])
    with pytest.raises(ReplayError, match=f"stopped after {len(pts)} of the {len(pts) + 3}"):
        replay(_row("georobust", BOX1, budget, more))
    # a change below the tolerance is accepted
    xs = pts.xs.copy()
    xs[7, 0] += 1e-14
    replay(_row("georobust", BOX1, budget, Points(xs, pts.fs)))


def test_job_zones_skips_what_has_no_cover():
    budget = Budget(max_evals=20)
    _, _, pts = _live("random", BOX1, tent, budget)
    jz = job_zones(_row("random", BOX1, budget, pts))
    assert jz.zones is None and "no cover" in jz.note
    jz = job_zones(_row("georobust", BOX1, budget, pts).replace(status="failed", reason="boom"))
    assert jz.zones is None and "boom" in jz.note
    assert job_zones(_row("georobust", BOX1, budget, None)).zones is None


def test_plot_zones_draws_1d_and_2d(tmp_path):
    zm = zones(run("georobust", BOX1, tent, max_evals=40).cells(), EPS, lipschitz=L1)
    xs = np.linspace(-10, 10, 201)[:, None]
    assert plot_zones(zm, tmp_path / "a.png", landscape=(xs, tent(xs))).stat().st_size > 1000
    box = ParameterBox({"roll_deg": (-10.0, 10.0), "contrast": (0.8, 1.2)})
    z2 = zones(run("georobust-a", box, gate, max_evals=60).cells(), EPS, estimate=True)
    assert plot_zones(z2, tmp_path / "b.png").stat().st_size > 1000
    box3 = ParameterBox({"a": (0, 1), "b": (0, 1), "c": (0, 1)})
    with pytest.raises(ValueError, match="1-D and 2-D"):
        plot_zones(zones(run("direct", box3, lambda x: x.sum(axis=1), max_evals=20).cells(), EPS), tmp_path / "c.png")


def test_the_package_exposes_zones_where_they_live():
    assert vr.search.zones.zones is zones and vr.campaigns.zones_of_run is zones_of_run
    assert "zones_of_run" in vr.campaigns.__all__


@pytest.mark.parametrize("lipschitz", [None, 1e-3])
def test_a_breaching_vertex_marks_its_cell_breached(lipschitz):
    box = ParameterBox({"roll_deg": (-10.0, 10.0), "contrast": (0.8, 1.2)})

    def corner(x):  # breaches only at the vertex (+10°, 1.2); a constant far too small to see it
        return np.where((x[:, 0] > 9.99) & (x[:, 1] > 1.199), 5000.0, 20.0)

    opt = make_optimizer("georobust", box, max_evals=40, vertices=True)
    while len(x := opt.ask()):
        opt.tell(x, corner(x))
    cells = opt.cells()
    assert len(cells.extra_points) == 4 and cells.extra_values.max() == 5000.0
    assert cells.values.max() == 20.0  # no centre breaches
    zm = zones(cells, EPS, lipschitz=lipschitz)
    hit = zm.of("breached")
    assert len(hit) == 1 and hit[0].upper == (10.0, 1.2)  # the corner cell, never ruled out
    with pytest.raises(ValueError, match="4 extra points but 3 extra values"):
        Cells(box=cells.box, centers=cells.centers, half_widths=cells.half_widths, lower=cells.lower,
              upper=cells.upper, values=cells.values, failed=cells.failed, fractions=cells.fractions,
              extra_points=cells.extra_points, extra_values=cells.extra_values[:3])
