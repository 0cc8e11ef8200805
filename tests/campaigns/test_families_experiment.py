"""``reproduce families``: every perturbation family alone at its five nested levels, chained, with a grid reference."""

from __future__ import annotations

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.constants import EPS_SAFE_M, Verdict
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.paper.experiments import (
    EXPERIMENTS,
    FAMILY_GRID_POINTS,
    Options,
    experiment,
    family_grid_count,
)
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.report.build import build_report
from vbl_robust.report.evidence import SAFETY_FIGURE
from vbl_robust.report.html import fmt_num
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, levels_text, range_text, roll_box
from vbl_robust.store.core import ResultStore

TINY = Options(methods=("georobust", "random"), max_evals=6, family_grid=21)


def _blocks(spec):
    main = {b.boxes[0].box.names[0]: b for b in spec.blocks if b.role == "main"}
    ref = {b.boxes[0].box.names[0]: b for b in spec.blocks if b.role == "reference"}
    return main, ref


def test_every_family_has_five_nested_chained_levels_and_a_grid():
    spec = experiment("families").build(0, Options())
    main, ref = _blocks(spec)
    assert list(main) == list(ref) == list(PERTURBATIONS)
    assert spec.figures == ("families",) and EXPERIMENTS["families"].images == 100
    labels = [b.label for blk in main.values() for b in blk.boxes]
    assert len(set(labels)) == len(labels) == 5 * len(PERTURBATIONS)  # objectives and seeds are keyed by label
    for name, blk in main.items():
        p = PERTURBATIONS[name]
        assert blk.chain and blk.methods == ("georobust", "georobust-av", "random")
        assert blk.budgets == (Budget(max_evals=200, stop_at_breach=True),)
        assert [b.level for b in blk.boxes] == [1.0, 2.0, 3.0, 4.0, 5.0]
        bounds = [(float(b.box.lower[0]), float(b.box.upper[0])) for b in blk.boxes]
        assert bounds == [tuple(map(float, lv)) for lv in p.levels]
        for (lo0, hi0), (lo1, hi1) in zip(bounds, bounds[1:], strict=False):
            assert lo1 <= lo0 <= p.identity <= hi0 <= hi1  # nested, the identity inside
        assert all(b.label.startswith(f"{name} ") for b in blk.boxes)
        # the grid covers the largest level; every level's bounds and the identity are nodes
        (gbox,) = ref[name].boxes
        assert gbox == blk.boxes[-1] and ref[name].methods == ("grid",)
        (n,) = ref[name].options["grid"]["counts"]
        assert n >= FAMILY_GRID_POINTS and ref[name].budgets[0].max_evals == n
        nodes = np.linspace(*bounds[-1], n)
        for v in (p.identity, *(b for lv in bounds for b in lv)):
            assert np.min(np.abs(nodes - v)) < 1e-9, (name, v)
    # outwards from the identity, stopped at the first breach, where the lattice allows it
    order = {name: (b.options["grid"].get("order", "c"), b.budgets[0].stop_at_breach) for name, b in ref.items()}
    assert order["roll_deg"] == order["brightness"] == ("center-out", True)
    assert order["blur_px"] == order["noise_std"] == order["haze"] == ("c", True)
    assert order["contrast"] == order["gamma"] == ("c", False)
    for name, spec_ in PERTURBATIONS.items():
        for k, (lo, hi) in enumerate(spec_.levels, start=1):
            assert f"L{k} {range_text(lo, hi, spec_.unit)}" in spec.notes, name


def test_options_methods_grid_and_chain_ids():
    spec = experiment("families").build(0, Options(methods=("apgd",), family_grid=0))
    main, ref = _blocks(spec)
    assert not ref and all(b.methods == ("apgd",) for b in main.values())  # nothing else left: kept as given
    assert not _blocks(experiment("families").build(0, Options(grid_step_deg=0.0)))[1]
    spec = experiment("families").build(0, Options(methods=("georobust", "sobol", "apgd")))
    assert all(b.methods == ("georobust", "sobol") for b in _blocks(spec)[0].values())
    jobs = experiment("families").build(0, TINY).expand([("a", "fa")])
    chains = {}
    for j in jobs:
        if j.chain is not None:
            chains.setdefault((j.method, j.box.box.names[0]), set()).add(j.chain)
    assert all(len(c) == 1 for c in chains.values())  # one chain per family and method ...
    assert len({next(iter(c)) for c in chains.values()}) == len(chains)  # ... never shared between families
    with pytest.raises(ValueError, match="share their parameters"):
        Block(boxes=(roll_box(5), *experiment("families").build(0, TINY).blocks[1].boxes[-1:]), methods=("random",),
              budgets=(Budget(max_evals=5),), chain=True)


def test_grid_count_and_level_texts():
    assert family_grid_count(PERTURBATIONS["roll_deg"].levels, 0.0, 201) == 241  # 0.25° steps: ±2 … ±30 on nodes
    assert family_grid_count(PERTURBATIONS["contrast"].levels, 1.0, 201) == 211
    assert family_grid_count(PERTURBATIONS["haze"].levels, 0.0, 201) == 201
    assert family_grid_count(((-1 / 3, 1 / 3), (-1.0, 1.0)), 0.0, 5) == 7
    assert family_grid_count(((0.0, 0.1234567),), 0.0, 11) == 11  # no small common spacing: as requested
    assert levels_text([(-2, 2), (-5, 5)], "deg") == "±2/5°"
    assert levels_text([(0, 0.5), (0, 1)], "px") == "0 to 0.5/1 px"
    assert levels_text([(0.9, 1.1), (0.8, 1.25), (0.4, 2.5)], "factor") == "[0.9, 1.1] … [0.4, 2.5]"
    assert range_text(-0.05, 0.05, "full scale") == "±0.05 FS"


def test_estimate_and_planned_work():
    from vbl_robust.cli import app
    from vbl_robust.paper.estimate import planned_work

    spec = experiment("families").build(0, Options(max_evals=10, family_grid=0))
    assert planned_work(spec, 3) == (3 * len(PERTURBATIONS) * 5 * 3 * 10, 0.0)  # georobust, georobust-av, random
    evals, _ = planned_work(experiment("families").build(0, Options(max_evals=10)), 1)
    grids = sum(b.budgets[0].max_evals for b in experiment("families").build(0, Options()).blocks
                if b.role == "reference")
    assert evals == len(PERTURBATIONS) * 5 * 3 * 10 + grids
    # 2 images x 10 families x 5 levels x 3 methods (georobust, georobust-av, random) x 200 evaluations
    res = CliRunner().invoke(app, ["reproduce", "families", "--estimate", "--oracle", "--images", "2",
                                   "--family-grid", "0", "--probe-seconds", "0.2"])
    assert res.exit_code == 0, res.output
    assert re.search(r"families\s+2 images\s+≤\s+60000 evaluations", res.output), res.output


def _cells(html: str) -> list[list[str]]:
    return [re.findall(r"<td[^>]*>(.*?)</td>", tr) for tr in re.findall(r"<tr[^>]*>(.*?)</tr>", html)]


def _survival(flags) -> float:
    return 100.0 * float(np.mean(flags))


@pytest.mark.slow
def test_families_end_to_end_on_the_oracle(tmp_path, small_samples):
    # a fixed corner error: one far image breaches unperturbed (every family at L1, larger levels implied), one
    # breaches under roll at a larger level, the closest one survives
    det = DetectorSpec("oracle", options={"noise_px": 0.2, "fail_outside": True})
    spec = experiment("families").build(0, TINY)
    samples = small_samples[3:6]
    with ResultStore(tmp_path / "results.sqlite") as st:
        summary = run_campaign(spec, samples, st, detector=det)
        rows = st.jobs(with_points=True)
    assert summary.status == "finished" and summary.not_measured == 0
    main = [r for r in rows if r.role == "main"]
    # every job has its row: a breach in one family's chain implies nothing in another's
    assert len(main) == len(samples) * len(PERTURBATIONS) * 5 * 2
    assert any(r.status == "implied" for r in main) and any(r.verdict is Verdict.NO_BREACH_FOUND for r in main)
    for r in main:
        if r.status == "implied":  # implied only by a breach of the same family, chain and method, at a lower level
            src = [q for q in main if q.chain == r.chain and q.verdict is Verdict.BREACH and q.status == "done"]
            assert len(src) == 1 and src[0].box.box.names == r.box.box.names and src[0].box.level < r.box.level
            assert src[0].method == r.method and src[0].sample_id == r.sample_id
    html = build_report(tmp_path).read_text()
    stems = {p.stem for p in (tmp_path / "figures").glob("*.png")}
    assert {"families_ranking", "families_survival"} <= stems  # besides them only the zones section's figures
    # besides them only the first screen's survival per box and the zones section's figures
    assert all(s.startswith("zones_") for s in stems - {"families_ranking", "families_survival", SAFETY_FIGURE})
    table = {(c[1], c[2]): c for c in _cells(html) if len(c) == 11 and c[0].isdigit()}
    grids = [r for r in rows if r.role == "reference"]
    assert len(grids) == len(samples) * len(PERTURBATIONS)
    for name, spec_ in PERTURBATIONS.items():
        breached_any = {s.id: [False] * 5 for s in samples}
        for method, label in (("georobust", "GeoRobust"), ("random", "Random")):
            cells = table[(name, label)]
            for k in range(1, 6):
                at = [r for r in main if r.method == method and r.box.box.names[0] == name and r.box.level == k]
                assert len(at) == len(samples)
                assert cells[3 + k] == fmt_num(_survival([r.worst_m <= EPS_SAFE_M for r in at])), (name, method, k)
                for r in at:
                    breached_any[r.sample_id][k - 1] |= r.worst_m > EPS_SAFE_M
        for g in (g for g in grids if g.box.box.names[0] == name):
            for k, (lo, hi) in enumerate(spec_.levels, start=1):
                inside = (g.points.xs[:, 0] >= lo - 1e-9) & (g.points.xs[:, 0] <= hi + 1e-9)
                breached_any[g.sample_id][k - 1] |= bool(np.any(~(g.points.fs[inside] <= EPS_SAFE_M)))
        # "any method": breached at level k when breached at some level <= k (nested levels)
        surv = [_survival([not any(b[:k]) for b in breached_any.values()]) for k in range(1, 6)]
        cells = table[(name, "any method (grid included)")]
        assert cells[4:9] == [fmt_num(v) for v in surv], name
        for t, cell in ((50, cells[9]), (10, cells[10])):
            k = next((k for k, v in enumerate(surv, start=1) if v < t), None)
            assert cell == ("not reached" if k is None else
                            f"L{k} ({range_text(*spec_.levels[k - 1], spec_.unit)})"), (name, t)
    # ranked by the two levels (not reached last)
    ranked = sorted((int(c[0]), c[9:]) for c in table.values() if c[2] == "any method (grid included)")
    assert [r for r, _ in ranked] == list(range(1, len(PERTURBATIONS) + 1))
    keys = [tuple(6 if v == "not reached" else int(v[1]) for v in cells) for _, cells in ranked]
    assert keys == sorted(keys) and keys[0] < keys[-1]
