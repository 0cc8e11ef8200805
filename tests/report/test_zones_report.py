"""The report's "Vulnerability zones" section, on tiny runs with a detector whose failure set is known
(tests/cli/zones_helpers.RollGate: no detection, 5000 m, where roll > 4°)."""

from __future__ import annotations

import json
import re
import shutil
import sqlite3
import zlib
from pathlib import Path

import numpy as np
import pytest
import torch

from vbl_robust.analysis.readoff import main_rows
from vbl_robust.campaigns.replay import zones_of_run
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.report import zone_section as B
from vbl_robust.report.build import build_report
from vbl_robust.report.html import fmt_num
from vbl_robust.report.rows import Context
from vbl_robust.search.zones import CLASSES
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box, roll_contrast_box
from vbl_robust.specs.settings import PipelineSettings
from vbl_robust.store.core import ResultStore
from vbl_robust.store.digest import reseal

GATE = 4.0
GATED = DetectorSpec("factory", "zones_helpers:RollGate")
BOX = roll_contrast_box(10.0, (0.8, 1.2))


@pytest.fixture(scope="module", autouse=True)
def helpers_importable():
    """RollGate lives in tests/cli (importable there by name, not from here)."""
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(Path(__file__).parents[1] / "cli"))
    yield
    mp.undo()


@pytest.fixture(scope="module")
def samples():
    from vbl_robust.scenes.generate import generate

    torch.set_num_threads(1)
    return generate(3, seed=1, width=96, height=96)


def _run(out: Path, spec: CampaignSpec, samples, detector=GATED) -> Path:
    with ResultStore(out / "results.sqlite") as store:
        run_campaign(spec, samples, store, detector=detector)
    return out


@pytest.fixture(scope="module")
def gated_2d(tmp_path_factory, samples):
    """Three images, GeoRobust / DIRECT / random on a roll × contrast box, a landscape grid on the first image."""
    spec = CampaignSpec("zones-report", (
        Block(boxes=(BOX,), methods=("georobust", "direct", "random"),
              budgets=(Budget(max_evals=40, stop_at_breach=False),)),
        Block(boxes=(BOX,), methods=("grid",), budgets=(Budget(max_evals=45, stop_at_breach=False),),
              role="landscape", max_samples=1, options={"grid": {"counts": [9, 5]}}),
    ), seed=2, figures=("landscape", "per_image"))
    return _run(tmp_path_factory.mktemp("gated2d"), spec, samples)


def _context(run: Path, store: ResultStore) -> Context:
    spec = store.spec()
    return Context(store, spec, run, main_rows(store, spec), store.samples())


def _expected(run: Path) -> dict[str, dict[str, float]]:
    """Per method: mean and median % of Θ per class, from zones_of_run on the same basis (the method's estimate)."""
    out: dict[str, dict[str, float]] = {}
    jobs = [j for j in zones_of_run(run, roles=("main",), estimate=True) if j.zones is not None]
    for m in sorted({j.method for j in jobs}):
        fr = [j.zones.fractions for j in jobs if j.method == m]
        out[m] = {"n": len(fr)}
        for c in CLASSES:
            v = 100.0 * np.array([f[c] for f in fr])
            out[m][f"{c}_mean"], out[m][f"{c}_median"] = float(v.mean()), float(np.median(v))
    return out


def _section(html: str) -> str:
    m = re.search(r"<h2[^>]*>Vulnerability zones</h2>(.*?)(<h2|$)", html, re.S)
    assert m, "no zones section"
    return m.group(1)


def test_the_section_draws_the_landscape_image_and_tables_every_job(gated_2d):
    html = build_report(gated_2d).read_text()
    sec = _section(html)
    # after the landscape, before the per-image table
    assert html.index("Loss landscape") < html.index("Vulnerability zones") < html.index("Per image")
    figs = gated_2d / "figures"
    assert (figs / "zones_georobust.png").stat().st_size > 5000 and (figs / "zones_direct.png").stat().st_size > 5000
    assert not (figs / "zones_random.png").exists() and not list(figs.glob("zones_grid*"))
    assert sec.count("data:image/png;base64,") == 2  # the landscape image only, one figure per covering method
    assert "estimate — not sound" in sec and "sound under L" not in sec and "Basis:" in sec
    # the table: one line per covering method (random keeps no cover), 3 jobs each, numbers as zones_of_run's
    expected = _expected(gated_2d)
    assert set(expected) == {"georobust", "direct"} and all(e["n"] == 3 for e in expected.values())
    with ResultStore.open_existing(gated_2d) as store:
        ctx = _context(gated_2d, store)
        jobs, left_out = B.zone_jobs(ctx)
        lines = B.zone_lines(jobs)
    assert not left_out and [line["method"] for line in lines] == ["GeoRobust", "DIRECT"]
    for line, m in zip(lines, ("georobust", "direct"), strict=True):
        assert line["n"] == expected[m]["n"] and line["skipped"] == 0 and line["basis"] == "estimate"
        for k in (f"{c}_{s}" for c in CLASSES for s in ("mean", "median")):
            assert line[k] == pytest.approx(expected[m][k], abs=1e-9), (m, k)
            assert f">{fmt_num(line[k])}<" in sec, (m, k)
        assert sum(line[f"{c}_mean"] for c in CLASSES) == pytest.approx(100.0)
        assert line["breached_mean"] > 0  # every search met the failure set
    # the breached zones are where the detector fails: roll > 4°
    for j in jobs:
        assert all(z.center[0] > GATE and z.value == 5000.0 for z in j.map.of("breached"))


def test_a_job_that_does_not_replay_is_listed_as_skipped(gated_2d, tmp_path):
    out = tmp_path / "tampered"
    shutil.copytree(gated_2d, out)
    con = sqlite3.connect(out / "results.sqlite")
    # DIRECT's job on the landscape image: drawn, were it not tampered with
    key, blob = con.execute("SELECT key, points FROM jobs WHERE method = 'direct' AND sample_id = "
                            "(SELECT sample_id FROM jobs WHERE role = 'landscape')").fetchone()
    d = json.loads(zlib.decompress(blob))
    d["xs"][3][0] += 0.01
    con.execute("UPDATE jobs SET points = ? WHERE key = ?", (zlib.compress(json.dumps(d).encode()), key))
    with con:  # re-digested: a store that does not replay (other code), not a row changed since its commit
        reseal(con)
    con.close()
    sec = _section(build_report(out).read_text())
    assert "1 job(s) skipped" in sec and "replay failed" in sec and "evaluation 3" in sec
    assert sec.count("data:image/png;base64,") == 1 and "Not drawn (no zones): DIRECT (replay failed" in sec
    with ResultStore.open_existing(out) as store:
        lines = B.zone_lines(B.zone_jobs(_context(out, store))[0])
    direct = next(line for line in lines if line["method"] == "DIRECT")
    assert (direct["n"], direct["skipped"]) == (2, 1)


def test_the_replay_budget_keeps_whole_images_landscape_image_first(gated_2d, tmp_path, monkeypatch):
    monkeypatch.setattr(B, "ZONES_REPLAY_POINTS", 1)
    with ResultStore.open_existing(gated_2d) as store:
        ctx = _context(tmp_path, store)
        grid = store.jobs(kind="search", role="landscape")[0]
        jobs, left_out = B.zone_jobs(ctx, grid.sample_id)
    assert {j.row.sample_id for j in jobs} == {grid.sample_id} and len(left_out) == 2
    assert len(jobs) == 2  # GeoRobust and DIRECT of that image
    sec = _section(build_report(gated_2d, tmp_path / "capped").read_text())
    assert "the other 2 image(s) were not replayed" in sec and (tmp_path / "capped/figures/zones_georobust.png").exists()


def test_a_run_with_a_lipschitz_constant_is_labelled_sound_1d(tmp_path, samples):
    spec = CampaignSpec("zones-sound", (
        Block(boxes=(roll_box(10.0),), methods=("georobust", "grid"), budgets=(Budget(max_evals=30, stop_at_breach=False),),
              options={"grid": {"counts": [30]}}),
        Block(boxes=(roll_box(10.0),), methods=("grid",), budgets=(Budget(max_evals=81, stop_at_breach=False),),
              role="landscape", max_samples=1, options={"grid": {"counts": [81]}}),
    ), settings=PipelineSettings(lipschitz=400.0), figures=("landscape",))
    run = _run(tmp_path, spec, samples[:1])
    sec = _section(build_report(run).read_text())
    assert "sound under L = 400 (2-norm of real units)" in sec and "not sound" not in sec
    assert (run / "figures" / "zones_georobust.png").exists() and (run / "figures" / "zones_grid.png").exists()
    with ResultStore.open_existing(run) as store:
        jobs, _ = B.zone_jobs(_context(run, store))
    assert {j.map.basis for j in jobs} == {"sound"}
    sound = {j.key: j.zones.fractions for j in zones_of_run(run, roles=("main",))}  # the run's constant by default
    assert all(j.map.fractions == sound[j.row.key] for j in jobs)
    assert all(z.center[0] > GATE for j in jobs for z in j.map.of("breached"))


def test_no_section_without_a_search_that_keeps_a_cover(tmp_path, samples):
    spec = CampaignSpec("zones-none", (
        Block(boxes=(BOX,), methods=("random",), budgets=(Budget(max_evals=8),)),
        Block(boxes=(BOX,), methods=("grid",), budgets=(Budget(max_evals=15),), role="landscape", max_samples=1,
              options={"grid": {"counts": [5, 3]}}),
    ), figures=("landscape", "per_image"))
    run = _run(tmp_path, spec, samples[:1])
    html = build_report(run).read_text()
    assert "Loss landscape" in html and "Vulnerability zones" not in html
    assert not list((run / "figures").glob("zones_*"))


def test_a_search_stopped_at_its_first_point_has_no_estimate_and_rules_nothing_out(tmp_path, samples):
    grid = {"counts": [3, 3], "order": "center-out", "batch_size": 1}
    spec = CampaignSpec("zones-one", (Block(boxes=(BOX,), methods=("grid",), budgets=(Budget(max_evals=9),),
                                            options={"grid": grid}),), figures=("per_image",))
    run = _run(tmp_path, spec, samples[:1], DetectorSpec("factory", "zones_helpers:RollGate", options={"above": -1.0}))
    sec = _section(build_report(run).read_text())
    assert "No 1-D or 2-D landscape grid" in sec and "skipped (no zones)" not in sec
    with ResultStore.open_existing(run) as store:
        [job] = B.zone_jobs(_context(run, store))[0]
    # the centre breached and the grid stopped: no two neighbours, no slope estimate, so no constant at all
    assert job.row.nfev == 1 and job.map.cells.lipschitz_estimate is None and job.map.basis == "none"
    [line] = B.zone_lines([job])
    assert line["basis"] == "none" and line["n"] == 1 and line["ruled_out_mean"] == 0.0
    # the centre node's cell: half a spacing (a quarter of each side) either way
    assert line["breached_mean"] == pytest.approx(25.0) and line["undecided_mean"] == pytest.approx(75.0)


def test_the_zone_figure_takes_a_2d_landscape_as_a_heat_map(tmp_path):
    from vbl_robust.report.zone_figure import plot_zones
    from vbl_robust.search.api import make_optimizer
    from vbl_robust.search.zones import zones

    box = BOX.box
    f = lambda x: np.where(x[:, 0] > GATE, 5000.0, 20.0 + np.abs(x[:, 0]))  # noqa: E731
    opt = make_optimizer("georobust", box, max_evals=30)
    while len(x := opt.ask()):
        opt.tell(x, f(x))
    zm = zones(opt.cells(), 1000.0, estimate=True)
    lattice = np.stack(np.meshgrid(np.linspace(-10, 10, 9), np.linspace(0.8, 1.2, 5)), -1).reshape(-1, 2)
    scattered = np.random.default_rng(0).uniform(box.lower, box.upper, size=(40, 2))
    for name, xs in (("lattice", lattice), ("partial", lattice[:20]), ("scattered", scattered)):
        assert plot_zones(zm, tmp_path / f"{name}.png", landscape=(xs, f(xs))).stat().st_size > 5000
    with pytest.raises(ValueError, match=r"landscape must be \(xs \(n, 2\)"):
        plot_zones(zm, tmp_path / "bad.png", landscape=(lattice[:, :1], f(lattice)))
