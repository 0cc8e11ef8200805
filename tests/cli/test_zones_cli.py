"""``vbl-robust zones RUN`` and ``audit --refine-zones`` on tiny runs (oracle and a detector with a known failure set)."""

from __future__ import annotations

import csv
import io
import json
import math
import sys

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import vbl_robust.search.api as search_api
from vbl_robust.campaigns.replay import replay, zones_of_run
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.cli import app
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_contrast_box
from vbl_robust.stats import Rate
from vbl_robust.store.core import ResultStore
from vbl_robust.store.digest import reseal

runner = CliRunner()
SMALL = ["--oracle", "--oracle-noise", "0.5", "--width", "256", "--height", "256", "--quiet"]
GATE = 4.0  # zones_helpers.RollGate: no detection (5000 m) where roll > 4°


@pytest.fixture(scope="module")
def gated_run(tmp_path_factory):
    """A two-image campaign with RollGate; the live optimizers of its searches, captured as they ran."""
    from vbl_robust.scenes.generate import generate

    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("gated")
    box = roll_contrast_box(10.0, (0.8, 1.2))
    blocks = (
        Block(boxes=(box,), methods=("georobust", "georobust-a", "direct", "random"),
              budgets=(Budget(max_evals=40), Budget(max_evals=40, stop_at_breach=False))),
        Block(boxes=(box,), methods=("grid",), budgets=(Budget(max_evals=60),), role="landscape",
              options={"grid": {"counts": [9, 5]}}),
    )
    spec = CampaignSpec("zones-test", blocks, seed=2)
    live = []
    real = search_api.make_optimizer

    def capture(*args, **kwargs):
        opt = real(*args, **kwargs)
        if sys._getframe(1).f_code is search_api.maximize.__code__:  # a search's; spec.check builds some to check
            live.append(opt)
        return opt

    mp = pytest.MonkeyPatch()
    mp.setattr(search_api, "make_optimizer", capture)
    try:
        with ResultStore(out / "results.sqlite") as store:
            run_campaign(spec, generate(2, seed=1, width=96, height=96), store,
                         detector=DetectorSpec("factory", "zones_helpers:RollGate"))
    finally:
        mp.undo()
    return out, live


def test_replayed_cells_are_the_live_optimizers(gated_run):
    out, live = gated_run
    with ResultStore.open_existing(out) as store:
        spec = store.spec()
        rows = store.jobs(kind="search", with_points=True)
    assert len(rows) == 2 * (4 * 2 + 1) and all(r.status == "done" for r in rows)
    checked = 0
    assert len(live) == len(rows)  # the local executor runs the jobs in the store's order
    for row, opt in zip(rows, live, strict=True):
        assert opt.name == row.method and np.array_equal(opt.result().xs, row.points.xs)
        assert np.array_equal(opt.result().fs, row.points.fs, equal_nan=True)
        if not opt.covers:
            continue
        a, b = replay(row, spec).cells(), opt.cells()
        if b is None:  # breached inside its first batch (the record ends there, the method never saw a batch)
            assert a is None and row.verdict == "breach" and row.trace[0].extra.get("partial")
            continue
        for k in ("centers", "half_widths", "lower", "upper", "fractions", "failed"):
            assert np.array_equal(getattr(a, k), getattr(b, k)), (row.method, k)
        assert np.array_equal(a.values, b.values, equal_nan=True)
        checked += 1
    assert checked >= 2 * (3 + 1)  # every search without early stop, and the landscape grids


def test_zones_of_a_run_with_a_known_failure_set(gated_run):
    out, _ = gated_run
    jobs = zones_of_run(out, estimate=True)
    done = [j for j in jobs if j.zones is not None]
    # no zones: random (no cover), or a search that breached inside its first batch (its record ends at the breach
    # and the method never completed a batch: no cells)
    assert {j.method for j in jobs if j.zones is None and "no cover" in j.note} == {"random"}
    assert all(j.note == "no complete batch: no cells" for j in jobs if j.zones is None and j.method != "random")
    assert sum(j.role == "main" for j in done) >= 2 * 3  # every DIRECT-family search without early stop
    for j in done:
        fr = j.zones.fractions
        assert math.isclose(sum(fr.values()), 1.0, abs_tol=1e-12) and j.zones.basis == "estimate"
        assert fr["breached"] > 0  # every search met the failure set (most of its first division lies in it)
        for z in j.zones.of("breached"):
            assert z.center[0] > GATE and z.value == 5000.0
            assert z.box.names == ("roll_deg", "contrast")
        for z in j.zones.zones:
            if z.center[0] <= GATE:
                assert z.cls != "breached"
    # without a constant nothing is ruled out; the breached zones do not depend on it
    plain = {j.key: j for j in zones_of_run(out, roles=("main",))}
    for j in done:
        if j.role == "main":
            assert plain[j.key].zones.fractions["ruled_out"] == 0.0
            assert plain[j.key].zones.fractions["breached"] == j.zones.fractions["breached"]


def test_zones_command_json_and_csv(gated_run, tmp_path):
    out, _ = gated_run
    res = runner.invoke(app, ["zones", str(out), "--estimate"])
    assert res.exit_code == 0, res.output
    body = json.loads(res.stdout)
    assert len(body["jobs"]) + len(body["skipped"]) == 18 and len(body["jobs"]) >= 2 * (3 + 1)
    assert sum("no cover" in s["note"] for s in body["skipped"]) == 4
    assert all("no cover" in s["note"] or "no complete batch" in s["note"] for s in body["skipped"])
    job = body["jobs"][0]
    assert {"key", "sample_id", "method", "box", "fractions", "zones", "basis", "basis_description"} <= set(job)
    assert "not sound" in job["basis_description"]
    z = job["zones"][0]
    assert set(z) == {"class", "value", "bound", "fraction", "bounds", "center"}
    assert set(z["bounds"]) == {"roll_deg", "contrast"} and z["bounds"]["roll_deg"][0] <= z["center"]["roll_deg"]
    assert "note: skipped 4 random job(s): keeps no cover of the box (no zones)" in res.stderr  # one line per reason
    assert len(res.stderr.splitlines()) == len({(s["method"], s["note"]) for s in body["skipped"]}) + len(
        {j["method"] for j in body["jobs"] if j.get("note")})

    res = runner.invoke(app, ["zones", str(out), "--lipschitz", "1,1", "--format", "csv", "--role", "landscape",
                              "--out", str(tmp_path / "z.csv"), "--plot", str(tmp_path / "plots")])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(io.StringIO((tmp_path / "z.csv").read_text())))
    assert len(rows) == 2 * 45 and {r["method"] for r in rows} == {"grid"} and {r["basis"] for r in rows} == {"sound"}
    assert {"roll_deg_lower", "roll_deg_upper", "contrast_center", "class", "bound", "fraction_breached"} <= set(rows[0])
    for key in {r["key"] for r in rows}:
        assert math.isclose(sum(float(r["fraction"]) for r in rows if r["key"] == key), 1.0, abs_tol=1e-12)
    assert all(float(r["roll_deg_center"]) > GATE for r in rows if r["class"] == "breached")
    assert len(list((tmp_path / "plots").glob("*.png"))) == 2


@pytest.mark.parametrize("args, message", [
    (["--lipschitz", "3", "--estimate"], "exclusive"),
    (["--format", "xml"], "--format"),
    (["--role", "best"], "--role"),
    (["--norm", "7"], "--norm"),
    (["--lipschitz", "abc"], "--lipschitz abc"),
    (["--lipschitz", "1,2,3"], "one per parameter"),
])
def test_zones_command_user_errors(gated_run, args, message):
    res = runner.invoke(app, ["zones", str(gated_run[0]), *args])
    assert res.exit_code == 2 and message in res.output


def test_zones_command_on_a_missing_run(tmp_path):
    res = runner.invoke(app, ["zones", str(tmp_path / "nothing")])
    assert res.exit_code == 2 and "no results store" in res.output


def test_zones_command_fails_loudly_on_a_store_that_does_not_replay(gated_run, tmp_path):
    import shutil
    import sqlite3
    import zlib

    out = tmp_path / "tampered"
    shutil.copytree(gated_run[0], out)
    con = sqlite3.connect(out / "results.sqlite")
    key, d = next((k, d) for k, b in con.execute("SELECT key, points FROM jobs WHERE method = 'direct'")
                  if len((d := json.loads(zlib.decompress(b)))["xs"]) > 3)
    d["xs"][3][0] += 0.01
    con.execute("UPDATE jobs SET points = ? WHERE key = ?", (zlib.compress(json.dumps(d).encode()), key))
    with con:  # re-digested: a store that does not replay (other code), not a row changed since its commit
        reseal(con)
    con.close()
    res = runner.invoke(app, ["zones", str(out)])
    assert res.exit_code == 2 and "replay failed" in res.output and "evaluation 3" in res.output


def test_audit_refine_zones(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "1", "--roll", "10", "--contrast", "0.8,1.2",
                              "--methods", "georobust,random", "--max-evals", "30", "--no-early-stop", "--no-landscape",
                              "--no-report", "--refine-zones", "40", *SMALL])
    assert res.exit_code == 0, res.output
    body = json.loads((out / "zones_refined.json").read_text())
    assert body["budget_per_job"] == 40
    [job] = [j for j in body["jobs"] if j["method"] == "georobust"]
    assert [j["note"] for j in body["jobs"] if j["method"] == "random"] == ["random: keeps no cover of the box (no zones)"]
    assert job["basis"] == "estimate" and "not sound" in job["basis_description"]
    assert 0 <= job["evaluations"] <= 40
    assert math.isclose(sum(job["after"].values()), 1.0, abs_tol=1e-12)
    # refinement spends evaluations exactly when there is something undecided to refine
    assert (job["evaluations"] > 0) == (job["before"]["undecided"] > 0)
    assert "refined zones:" in res.output


def _md_rows(text: str) -> dict[str, list[str]]:
    """Markdown table rows by their first cell (the header and rule skipped)."""
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in text.splitlines() if ln.startswith("| ")]
    return {r[0]: r[1:] for r in rows[1:]}


def test_zones_markdown_is_the_mean_of_the_job_fractions(gated_run):
    out, _ = gated_run
    res = runner.invoke(app, ["zones", str(out), "--role", "main", "--estimate", "--format", "md"])
    assert res.exit_code == 0, res.output
    assert "basis: each search's own estimate (not sound)" in res.output and "random 4" in res.output
    jobs = [j for j in zones_of_run(out, roles=("main",), estimate=True) if j.zones is not None]
    rows = _md_rows(res.output)
    for method in ("georobust", "georobust-a", "direct"):
        mine = [j.zones for j in jobs if j.method == method]
        assert rows[method][1] == str(len(mine))  # jobs (one box here: one row per method)
        assert rows[method][3] == f"{100 * np.mean([z.fractions['breached'] for z in mine]):.1f}"
        assert int(rows[method][2]) == sum(z.fractions["breached"] > 0 for z in mine)


def test_report_markdown_survival_table_from_the_store(gated_run, tmp_path):
    out, _ = gated_run
    res = runner.invoke(app, ["report", str(out), "--format", "md"])
    assert res.exit_code == 0, res.output
    assert "2 images measured by every method (of 2 started)" in res.output
    with ResultStore.open_existing(out) as store:
        spec = store.spec()
        from vbl_robust.analysis.readoff import main_rows
        from vbl_robust.analysis.summary import summarize

        lines = summarize(main_rows(store, spec, with_trace=False), spec.settings.eps_safe_m)
    survival = res.output.split("Breaches by kind")[0]
    rows = _md_rows(survival)
    head = next(ln for ln in survival.splitlines() if ln.startswith("| method"))
    budgets = [c.strip() for c in head.strip().strip("|").split("|")][1:]  # two budgets: a column each
    assert sorted(budgets) == sorted({ln.budget_label for ln in lines}) and len(budgets) == 2
    for ln in lines:
        ci = ln.survival_rate.ci
        cell = f"{ln.survival:.1f} [{ci.low:.1f}, {ci.high:.1f}] ({ln.breaches})"
        assert rows[ln.method][budgets.index(ln.budget_label)] == cell
    assert "any of them" in rows and "Landscape grid on image" in res.output  # the dense grid's found / true ratios
    # refused: md prints, it writes nothing; --with needs md and the same experiment
    for args, msg in ((["--format", "md", "--out", str(tmp_path)], "--format md prints"),
                      (["--with", str(out)], "--with belongs to --format md"),
                      (["--format", "pdf"], "--format pdf")):
        res = runner.invoke(app, ["report", str(out), *args])
        assert res.exit_code == 2 and msg in res.output, res.output


def union_all_of(lines, where):
    """(images, fixed) of the union's line over every image at ``where`` in a compare table."""
    (line,) = [ln for ln in lines if ln[0] == "any of them" and ln[1] == where and ln[2] == "all"]
    return int(line[3]), int(line[6])


def test_report_compare_pairs_two_runs_per_image(gated_run, tmp_path):
    """Before: the gated detector (breaches wherever roll > 4°); after: the same campaign on the plain oracle (no
    breach). Every image a method breached before is "fixed", none is new; the counts pair per image."""
    from vbl_robust.scenes.generate import generate

    before, _ = gated_run
    with ResultStore.open_existing(before) as st:
        spec = st.spec()
        rows = [r for r in st.jobs(kind="search", role="main", with_trace=False)]
    after = tmp_path / "after"
    with ResultStore(after / "results.sqlite") as store:
        run_campaign(spec, generate(2, seed=1, width=96, height=96), store, detector=DetectorSpec("oracle"))
    res = runner.invoke(app, ["report", str(before), "--format", "md", "--compare", str(after)])
    assert res.exit_code == 0, res.output
    lines = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in res.output.splitlines()
             if ln.startswith("| ")][1:]
    checked = 0
    union_env: dict[str, dict[str, tuple[int, int]]] = {}
    for method, where, envelope, n, surv_before, surv_after, fixed, new, _p in lines:
        if method == "any of them":
            if envelope != "all":
                union_env.setdefault(where, {})[envelope] = (int(n), int(fixed))
            continue
        assert envelope == "all"
        hits = {r.sample_id for r in rows if r.method == method and f"{r.box_label}, {r.budget_label}" == where
                and r.worst_m is not None and r.worst_m > 1000}
        assert (n, fixed, new, surv_after) == ("2", str(len(hits)), "0", Rate(2, 2).text(1, percent=False))
        assert surv_before == Rate(2 - len(hits), 2).text(1, percent=False)  # with its exact interval
        checked += 1
    assert checked == 8  # 4 methods x 2 budgets
    # the union per approach envelope splits the union over every image
    assert len(union_env) == 2  # one box, two budgets
    for where, per_env in union_env.items():
        assert set(per_env) <= {"far", "medium", "close"}
        assert tuple(map(sum, zip(*per_env.values(), strict=True))) == union_all_of(lines, where)
    res = runner.invoke(app, ["report", str(before), "--format", "md", "--compare", str(tmp_path / "none")])
    assert res.exit_code == 2 and "no results store" in res.output
    # the HTML page: the curves overlaid, the same table, and the images whose union verdict changed
    res = runner.invoke(app, ["report", str(before), "--compare", str(after), "--out", str(tmp_path / "cmp")])
    assert res.exit_code == 0 and "compare.html" in res.output, res.output
    page = (tmp_path / "cmp" / "compare.html").read_text()
    assert page.count("data:image/png;base64,") == 1 and (tmp_path / "cmp" / "figures" / "compare_survival.png").is_file()
    union = {(f"{r.box_label}, {r.budget_label}", r.sample_id) for r in rows if r.worst_m is not None and r.worst_m > 1000}
    assert page.count('<td class="l">fixed</td>') == len(union) > 0 and '>new breach<' not in page
    assert f"Images whose verdict changed (any method), {len(union)}" in page
