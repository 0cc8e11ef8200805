"""``vbl-robust reproduce all``: every experiment in its own run directory, an index page, and --estimate."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.paper.estimate import Probe, expected_evals, expected_seconds, planned_work
from vbl_robust.paper.experiments import EXPERIMENTS, PAPER, Options

runner = CliRunner()
SMALL = ["--oracle", "--oracle-noise", "0.5", "--width", "128", "--height", "128", "--quiet", "--images", "1",
         "--max-evals", "4", "--grid-step", "0", "--iterations", "2", "--time-budgets", "0.05", "--eval-budgets", "4"]


def test_reproduce_all_runs_every_experiment_and_resumes(tmp_path):
    out = tmp_path / "paper"
    res = runner.invoke(app, ["reproduce", "all", "--out", str(out), *SMALL])
    assert res.exit_code == 0, res.output
    for name in EXPERIMENTS:
        assert (out / name / "results.sqlite").exists() and (out / name / "report.html").exists(), name
    index = (out / "index.html").read_text()
    assert all(f'href="{name}/report.html"' in index for name in EXPERIMENTS)
    assert "The paper&#x27;s claims, checked" in index or "The paper's claims, checked" in index
    assert (out / "claims.md").read_text().count("\n| ") == 9  # one table row per claim (header aside)
    # the rerun only has to find every job done (a rerun's report is tests/cli/test_audit.py's; the bundle below
    # builds every report again, from the stores)
    again = runner.invoke(app, ["reproduce", "all", "--out", str(out), *SMALL, "--no-report"])
    assert again.exit_code == 0 and "0 new jobs" in again.output

    # the committable bundle: per experiment its job table, report (figures beside it) and provenance; no store
    import json
    import re
    from urllib.parse import unquote

    import pyarrow.parquet as pq

    from vbl_robust.store.core import ResultStore

    bundle = tmp_path / "bundle"
    repro = tmp_path / "REPRODUCTION.md"
    repro.write_text("# prose before\n<!-- bundle:begin -->\nold table\n<!-- bundle:end -->\nprose after\n")
    res = runner.invoke(app, ["bundle", str(out), "--out", str(bundle), "--reproduction", str(repro), "--stores"])
    assert res.exit_code == 0, res.output
    text = repro.read_text()
    assert text.startswith("# prose before\n") and text.endswith("prose after\n") and "old table" not in text
    assert (bundle / "claims.md").read_text() in text and (bundle / "status.md").read_text() in text
    index = (bundle / "index.html").read_text()  # the bundle's own page: each report, its jobs, the claims
    assert all(f'href="{name}/report.html"' in index for name in EXPERIMENTS) and "claims, checked" in index
    status = (bundle / "status.md").read_text()
    with ResultStore.open_existing(out / "spatial-1d") as store:
        n_jobs_s1 = store.count()
    for name in EXPERIMENTS:
        with ResultStore.open_existing(out / name) as store:
            n_jobs = store.count()
        prov = json.loads((bundle / name / "provenance.json").read_text())
        assert prov["totals"]["jobs_done"] == n_jobs == prov["totals"]["jobs_planned"]
        assert prov["runs"][0]["code_version"] and prov["runs"][0]["detector"]["name"].startswith("oracle")
        assert prov["campaign"]["spec"]["name"] == name
        assert pq.read_table(bundle / name / "jobs.parquet").num_rows >= n_jobs
        page = (bundle / name / "report.html").read_text()
        assert f"<title>vbl-robust {name}</title>" in page
        # a bundle's report shows its figures from figures/ beside it (docs/conventions.md): no base64, every
        # picture the page links is there
        assert "data:image/png;base64," not in page and not (bundle / name / "results.sqlite").exists()
        linked = re.findall(r'<img[^>]* src="(figures/[^"]+)"', page)
        assert all((bundle / name / unquote(src)).is_file() for src in linked)
        assert name != "spatial-1d" or linked
        assert (bundle / name / "results.sqlite.xz").stat().st_size > 0
        assert f"| {name} | {n_jobs} / {n_jobs} |" in status
        card = index.split(f'<a href="{name}/report.html">{name}</a>')[1].split('<div class="card">')[0]
        assert f">{n_jobs} of {n_jobs} jobs, " in card  # the bundle index: one card per experiment
        t = prov["totals"]  # the searches' hours on the campaign's clock beside the wall and worker hours
        assert f"| {t['search_s'] / 3600:.2f} | {t['clock']} |" in status
    # a smaller run reproduces the bundle's rows (the check: reproduce EXPERIMENT --images 3), checked
    # against the bundle's job table (what stays committed) and against the store
    from vbl_robust.paper.bundle import compare_runs

    again = tmp_path / "again"
    res = runner.invoke(app, ["reproduce", "spatial-1d", "--out", str(again), "--workers", "1", "--check-against",
                              str(bundle), *SMALL, "--no-report"])  # the check compares rows, not reports
    assert res.exit_code == 0, res.output
    assert (f"spatial-1d: checked against {bundle / 'spatial-1d'}: {n_jobs_s1} rows, {n_jobs_s1} found there, "
            "0 with another finding") in res.output
    assert compare_runs(again, out / "spatial-1d") == {"rows": n_jobs_s1, "common": n_jobs_s1, "differ": [],
                                                       "drift": [], "drift_m": 0.0}
    runtime = compare_runs(out / "runtime-1d", bundle / "runtime-1d")  # read-off and time-budget rows too
    assert runtime["differ"] == [] and runtime["rows"] == pq.read_table(bundle / "runtime-1d" / "jobs.parquet").num_rows
    other = tmp_path / "other"  # another seed: other searches, no common row, exit code 1
    res = runner.invoke(app, ["reproduce", "spatial-1d", "--out", str(other), "--seed", "1", "--check-against",
                              str(bundle / "spatial-1d" / "jobs.parquet"), *SMALL, "--no-report"])
    assert res.exit_code == 1 and f"{n_jobs_s1} rows, 0 found there, {n_jobs_s1} with another finding (first: " in res.output
    res = runner.invoke(app, ["reproduce", "spatial-1d", "--out", str(tmp_path / "none"), "--check-against",
                              str(tmp_path / "nothing"), *SMALL])  # refused before any work
    assert res.exit_code == 2 and "--check-against" in res.output and not (tmp_path / "none").exists(), res.output
    # a fresh checkout resumes from the bundle's packed stores: nothing is run again
    fresh = tmp_path / "fresh"
    resumed = runner.invoke(app, ["reproduce", "all", "--out", str(fresh), "--resume-from", str(bundle), *SMALL,
                                  "--no-report"])  # what is checked is the restored rows (the reports: above)
    assert resumed.exit_code == 0, resumed.output
    assert resumed.output.count("store restored from") == len(EXPERIMENTS) and "0 new jobs" in resumed.output
    assert all(f"{name}: 0 new jobs" in resumed.output for name in EXPERIMENTS)
    missing = runner.invoke(app, ["bundle", str(tmp_path / "nothing"), "--out", str(bundle)])
    assert missing.exit_code == 2 and "no experiment run directory" in missing.output
    repro.write_text("no markers\n")
    unmarked = runner.invoke(app, ["bundle", str(out), "--out", str(tmp_path / "b2"), "--reproduction", str(repro)])
    assert unmarked.exit_code == 2 and "needs one <!-- bundle:begin -->" in unmarked.output
    assert not (tmp_path / "b2").exists()  # refused before any work


def test_estimate_prints_an_upper_bound_per_experiment():
    res = runner.invoke(app, ["reproduce", "all", "--estimate", "--oracle", "--images", "2", "--probe-seconds", "0.2"])
    assert res.exit_code == 0, res.output
    # on a CPU the run's clock is the process clock: the probe's rates are per CPU second (an idle core's)
    assert "evaluations per CPU second (process clock" in res.output and all(n in res.output for n in EXPERIMENTS)
    assert "h expected" in res.output and "upper bound" in res.output
    assert "probe rates: black box best of" in res.output  # how the rate was obtained (issue 50)
    paper = runner.invoke(app, ["reproduce", "paper", "--estimate", "--oracle", "--images", "2",
                                   "--probe-seconds", "0.2", "--clock", "wall"])
    assert paper.exit_code == 0, paper.output
    assert "evaluations per s black box" in paper.output
    assert all(name in paper.output for name in PAPER) and "families" not in paper.output and len(PAPER) == 7


def test_estimate_of_a_run_under_way_counts_its_jobs_left_at_their_pace(tmp_path):
    out = tmp_path / "pnp"
    res = runner.invoke(app, ["reproduce", "pnp-validation", "--oracle", "--images", "2", "--out", str(out),
                              "--no-report", "-q", "--workers", "1"])  # the run to estimate: its jobs in this process
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["reproduce", "pnp-validation", "--estimate", "--oracle", "--images", "5", "--out",
                              str(out), "--probe-seconds", "0.2"])
    assert res.exit_code == 0 and "(under way: 3 jobs left, ≈ " in res.output, res.output


def test_bad_clock_and_workers_are_refused_before_any_work(tmp_path):
    for args, message in ((["--clock", "gpu"], "--clock must be auto, process or wall, got 'gpu'"),
                          (["--workers", "-1"], "--workers must be >= 0")):
        res = runner.invoke(app, ["reproduce", "spatial-1d", "--out", str(tmp_path / "r"), *SMALL, *args])
        assert res.exit_code == 2 and message in res.output
        assert not (tmp_path / "r" / "results.sqlite").exists()


def test_two_workers_and_the_process_clock_are_recorded(tmp_path):
    from vbl_robust.store.core import ResultStore

    out = tmp_path / "r"
    res = runner.invoke(app, ["reproduce", "runtime-1d", "--out", str(out), *SMALL, "--workers", "2", "--no-report"])
    assert res.exit_code == 0, res.output
    with ResultStore.open_existing(out) as store:
        run = store.runs()[0]
        assert run.provenance.config["workers"] == 2 and run.provenance.config["clock"] == "process"
        assert store.spec().settings.clock == "process"


def test_expected_duration_follows_the_breach_shares():
    assert expected_evals(0.0, 200) == 200 and expected_evals(1.0, 200) == 1
    assert expected_evals(0.5, 200) == pytest.approx(2.0)
    spec = EXPERIMENTS["spatial-1d"].build(0, Options(grid_step_deg=0.0, methods=("random", "apgd")))
    never = Probe(rate=10.0, grad_rate=5.0)
    # no breach anywhere: every budget spent; APGD's evaluations at the gradient path's rate
    assert expected_seconds(spec, 2, never) == pytest.approx(2 * 6 * (200 / 10.0 + 200 / 5.0))
    labels = [b.label for b in spec.blocks[0].boxes]
    always = Probe(10.0, 5.0, {label: [1.0, 1.0] for label in labels})
    assert expected_seconds(spec, 2, always, workers=2) == pytest.approx(6 * (1 / 10.0 + 1 / 5.0))
    # nested boxes of a chain (distance profile): a breach at the smallest box ends the chain
    chain = EXPERIMENTS["distance-profile"].build(0, Options(grid_step_deg=0.0, methods=("random",)))
    first = chain.blocks[0].boxes[0].label
    assert expected_seconds(chain, 1, Probe(10.0, 5.0, {first: [1.0]})) == pytest.approx(1 / 10.0)


def test_planned_work_counts_budgets_and_grids():
    exp = EXPERIMENTS["spatial-1d"]
    evals, seconds = planned_work(exp.build(0, Options(grid_step_deg=0.0)), 3)
    # 6 boxes x 4 methods (both GeoRobusts, random, APGD) x 200 evaluations per image (no reference grid)
    assert evals == 3 * 6 * 4 * 200 and seconds == 0.0
    _, seconds = planned_work(EXPERIMENTS["runtime-1d"].build(0, Options(time_budgets=(0.5,), eval_budgets=(10,))), 2)
    assert seconds > 0
