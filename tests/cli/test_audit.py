"""``vbl-robust audit``, ``reproduce`` and ``report`` on tiny inputs (oracle detector, small images)."""

import csv
import json
import sqlite3

import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()
SMALL = ["--oracle", "--oracle-noise", "0.5", "--width", "128", "--height", "128", "--quiet"]


def test_audit_small_run_resumes_and_exports(tmp_path):
    out = tmp_path / "run"
    args = ["audit", "--out", str(out), "--n", "2", "--roll", "10", "--contrast", "0.8,1.2", "--methods",
            "georobust,random", "--max-evals", "6", "--workers", "1", "--csv", str(tmp_path / "a.csv"), "--parquet",
            str(tmp_path / "a.parquet"), *SMALL]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "5 new jobs, 0 already done" in res.output and (out / "report.html").exists()
    rows = list(csv.DictReader(open(tmp_path / "a.csv")))
    main = [r for r in rows if r["role"] == "main"]
    assert len(main) == 4 and {"worst_roll_deg", "worst_contrast", "verdict"} <= set(rows[0])
    assert pq.read_table(tmp_path / "a.parquet").num_rows == len(rows) == 5  # + the landscape grid
    res = runner.invoke(app, args)
    assert res.exit_code == 0 and "0 new jobs, 5 already done" in res.output
    # the same --out with other settings is refused with a clear message
    res = runner.invoke(app, [*args[:-len(SMALL) - 4], "--max-evals", "7", *SMALL])
    assert res.exit_code == 2 and "other settings" in res.output


def test_an_incomplete_run_exits_1_and_a_rerun_completes_it(tmp_path, monkeypatch):
    """A run that ends with jobs left (here: a sample whose jobs never come back, as when its worker dies) says so and
    exits 1 — `reproduce` after its other experiments too; rerunning the same command completes it and exits 0."""
    import vbl_robust.campaigns.runner as runner_mod

    real = runner_mod.run_sample_task

    def loses_the_second_sample(task, *args, **kwargs):
        if task.sample.id.endswith("1"):
            return iter(())
        return real(task, *args, **kwargs)

    out = tmp_path / "run"
    args = ["audit", "--out", str(out), "--n", "2", "--roll", "10", "--methods", "random", "--max-evals", "4",
            "--no-landscape", "--no-report", "--workers", "1", *SMALL]
    monkeypatch.setattr(runner_mod, "run_sample_task", loses_the_second_sample)
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and "1 new jobs" in res.output and "run incomplete" in res.output, res.output
    paper = ["reproduce", "paper", "--out", str(tmp_path / "paper"), "--images", "2", "--workers", "1",
             "--max-evals", "4", "--grid-step", "0", "--iterations", "2", "--time-budgets", "0.05",
             "--eval-budgets", "4", "--no-landscape", "--no-report", *SMALL]  # reports of incomplete runs:
    res = runner.invoke(app, paper)  # tests/report/test_build.py
    assert res.exit_code == 1 and res.output.count("run incomplete") == 7 and "claims:" in res.output, res.output
    monkeypatch.setattr(runner_mod, "run_sample_task", real)
    res = runner.invoke(app, args)
    assert res.exit_code == 0 and "1 new jobs, 1 already done" in res.output, res.output


@pytest.mark.parametrize("args, message", [
    (["--roll", "none"], "at least one of --roll, --contrast"),
    (["--methods", "magic"], "unknown method"),
    (["--executor", "gpu"], "--executor"),
    (["--lipschitz", "-1"], "--lipschitz"),
    (["--model", "missing.pt"], "missing.pt"),
    (["--seed", "-1"], "--seed"),
    (["--max-evals", "-3"], "--max-evals"),
    (["--max-seconds", "-1"], "--max-seconds"),
    (["--oracle", "--oracle-noise", "-2"], "--oracle-noise"),
    (["--width", "8"], "--width"),
])
def test_audit_user_errors(tmp_path, args, message):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--n", "1", "--width", "128", "--height", "128", *args])
    assert res.exit_code == 2 and message in res.output


def test_audit_lipschitz_can_certify(tmp_path):
    # the oracle without noise: L stays ~0 over the box; a (generous) Lipschitz bound certifies the grid's cover
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--n", "1", "--roll", "5", "--methods", "grid",
                              "--max-evals", "41", "--lipschitz", "10", "--no-landscape", "--oracle", "--width", "128",
                              "--height", "128", "--quiet", "--no-report"])
    assert res.exit_code == 0, res.output
    con = sqlite3.connect(tmp_path / "results.sqlite")
    assert con.execute("SELECT verdict, upper_bound < 1000 FROM jobs").fetchall() == [("certified", 1)]


def test_reproduce_and_report_commands(tmp_path):
    out = tmp_path / "conv"
    res = runner.invoke(app, ["reproduce", "convergence", "--images", "2", "--iterations", "4", "--workers", "1",
                              "--out", str(out), *SMALL])
    assert res.exit_code == 0, res.output
    assert (out / "figures" / "convergence.png").exists()
    (out / "report.html").unlink()
    res = runner.invoke(app, ["report", str(out), "--csv", str(tmp_path / "c.csv")])
    assert res.exit_code == 0 and (out / "report.html").exists() and (tmp_path / "c.csv").exists()
    res = runner.invoke(app, ["reproduce", "spatial-9d", "--out", str(tmp_path / "x")])
    assert res.exit_code == 2 and "unknown experiment 'spatial-9d'" in res.output
    res = runner.invoke(app, ["report", str(tmp_path / "nothing")])
    assert res.exit_code == 2 and "no results store" in res.output


def test_demo_audits_the_shipped_model_by_default(tmp_path):
    # issue 4's "done when": the demo runs on the shipped, validated model (no training, no download)
    out = tmp_path / "demo"
    res = runner.invoke(app, ["demo", "--out", str(out), "--n", "1", "--max-evals", "3", "--no-landscape", "--quiet"])
    assert res.exit_code == 0, res.output
    con = sqlite3.connect(out / "results.sqlite")
    methods = sorted(m for (m,) in con.execute("SELECT method FROM jobs WHERE status = 'done'"))
    assert methods == ["apgd", "georobust-av", "random"]
    report = (out / "report.html").read_text()
    assert "shipped model (runway_yolov8n_pose.pt) v" in report and "oracle detector returns" not in report


def test_a_refused_model_does_not_lock_the_run_directory(tmp_path):
    # issue 12, item 8: an audit refused before its first job leaves --out free for another detector
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    out = tmp_path / "run"
    base = ["audit", "--out", str(out), "--n", "1", "--roll", "5", "--methods", "random", "--max-evals", "3",
            "--no-landscape", "--no-report", "--width", "128", "--height", "128", "--quiet"]
    res = runner.invoke(app, [*base, "--model", str(bad)])
    assert res.exit_code == 2 and "trust" in res.output
    res = runner.invoke(app, [*base, "--oracle"])
    assert res.exit_code == 0, res.output
    assert "1 new jobs" in res.output


def test_method_options_are_recorded_and_checked(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "1", "--roll", "10", "--contrast", "0.8,1.2",
                              "--methods", "georobust-a", "--max-evals", "12", "--method-option",
                              "georobust-a.min_ratio=9", "--method-option", "georobust-a.alpha=3", "--no-landscape",
                              "--no-report", *SMALL])
    assert res.exit_code == 0, res.output
    con = sqlite3.connect(out / "results.sqlite")
    assert [json.loads(o) for o, in con.execute("SELECT options_json FROM jobs")] == [{"min_ratio": 9, "alpha": 3}]
    res = runner.invoke(app, ["reproduce", "spatial-2d", "--images", "1", "--methods", "georobust-a,random",
                              "--max-evals", "6", "--method-option", "georobust-a.min_ratio=3", "--no-landscape",
                              "--out", str(tmp_path / "s2d"), "--no-report", *SMALL])
    assert res.exit_code == 0, res.output
    con = sqlite3.connect(tmp_path / "s2d" / "results.sqlite")
    rows = con.execute("SELECT method, options_json, count(*) FROM jobs GROUP BY method, options_json").fetchall()
    assert [(m, json.loads(o), n) for m, o, n in rows] == [("georobust-a", {"min_ratio": 3}, 6), ("random", {}, 6)]


@pytest.mark.parametrize("command, value, message", [
    ("audit", "georobust-a.min_ratio", "expected METHOD.OPTION=VALUE"),
    ("audit", "magic.alpha=2", "unknown method 'magic'"),
    ("audit", "random.alpha=2", "method 'random' has no option 'alpha'"),
    ("audit", "georobust-a.min_ratio=0.5", "min_ratio must be a finite number >= 1, got 0.5"),
    ("audit", "georobust-a.min_ratio=[1", "is not a number"),
    ("audit", "apgd.n_iter=5", "no search runs method(s) ['apgd']"),
    ("reproduce", "apgd.n_iter=5", "no experiment here runs method(s) ['apgd']"),
])
def test_method_option_mistakes_are_one_line_errors(tmp_path, command, value, message):
    args = (["audit", "--n", "1", "--methods", "georobust-a"] if command == "audit"
            else ["reproduce", "spatial-2d", "--images", "1", "--methods", "georobust-a"])
    res = runner.invoke(app, [*args, "--out", str(tmp_path), "--method-option", value, *SMALL])
    assert res.exit_code == 2 and message in res.output, res.output


def test_the_summary_table_never_cuts_a_method_name(tmp_path):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--n", "1", "--roll", "5", "--methods",
                              "georobust,georobust-av", "--max-evals", "9", "--no-landscape", "--no-report",
                              "--oracle", "--width", "128", "--height", "128"])
    assert res.exit_code == 0, res.output
    assert "│ georobust-av " in res.output and "│ georobust " in res.output


@pytest.mark.parametrize("args, message", [
    (["--contrast", "-1,2"], "lower bound of 'contrast' must be >= 0"),
    (["--pnp", "foo"], "pnp: unknown solver 'foo'"),
    (["--contrast", "0.8,1.2", "--lipschitz", "1,2,3"], "lipschitz must be a number or 2 finite numbers"),
    (["--methods", "random,random"], "random given more than once"),
    (["--engine", "openvino"], "--engine openvino applies to a model, not to --oracle"),
    (["--device", "tpu"], "--device tpu applies to a model, not to --oracle"),
    (["--roll", "-5"], "--roll -5: a half-width must be > 0"),
    (["--contrast", "1.4,0.7"], "--contrast 1.4,0.7: expected lower < upper"),
    (["--parquet", "x.csv"], "--parquet x.csv: the file name must end in .parquet"),
    (["--address", "auto"], "--address auto applies to --executor ray only"),
    (["--executor", "ray", "--address", "127.0.0.1:1"], "--address 127.0.0.1:1: no Ray cluster answers at 127.0.0.1:1"),
    (["--executor", "ray", "--address", "ray://nohost"], "--address ray://nohost: expected host:port"),
    (["--executor", "dask"], "--executor must be one of local, ray, got 'dask'"),
    (["--sustain", "5"], "--sustain 5 applies to --sequences only"),
    (["--frames", "5"], "--frames 5 applies to --sequences only"),
    (["--rate", "2.5"], "--rate 2.5 applies to --sequences only"),
    (["--monitor-sigma", "0"], "--monitor-sigma must be a finite number of metres > 0, got 0.0"),
    (["--monitor-sigma", "300", "--methods", "random,apgd"], "--monitor-sigma: a gradient search (apgd) cannot run"),
    (["--monitor-sigma", "300", "--methods", "random"], "--monitor-sigma 300: the detector (oracle"),
])
def test_a_configuration_error_is_refused_before_any_work(tmp_path, args, message):
    """Not "every image unsafe" with exit 0: one line naming the setting and value, exit 2, nothing stored."""
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "1", "--max-evals", "5", *SMALL, *args])
    assert res.exit_code == 2 and message in res.output, res.output
    assert "Traceback" not in res.output and not (out / "results.sqlite").exists()


def test_the_api_refuses_the_same_configuration_errors(tmp_path):
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.space import ParameterBox
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, BoxSpec, CampaignSpec
    from vbl_robust.store.core import ResultStore

    box = BoxSpec(ParameterBox({"contrast": (-1.0, 2.0)}), "contrast [-1, 2]", 1.0)
    spec = CampaignSpec("t", (Block(boxes=(box,), methods=("random",), budgets=(Budget(max_evals=4),)),))
    with ResultStore(tmp_path / "r.sqlite") as st:
        with pytest.raises(ValueError, match="box contrast \\[-1, 2\\]: .*lower bound of 'contrast'"):
            run_campaign(spec, [], st, detector=DetectorSpec.oracle(0.5))
        assert st.count() == 0 and st.runs() == []


def test_oracle_noise_without_the_oracle_is_refused(tmp_path):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path / "r"), "--n", "1", "--oracle-noise", "2", "--quiet"])
    assert res.exit_code == 2 and "--oracle-noise 2 applies to --oracle only" in res.output


def test_an_out_or_export_path_that_cannot_be_written_is_refused_before_the_run(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = runner.invoke(app, ["audit", "--out", str(blocker), "--n", "1", *SMALL])
    assert res.exit_code == 2 and "is a file, not a run directory" in res.output and blocker.read_text() == "x"
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "1", "--csv", str(blocker / "x.csv"), *SMALL])
    assert res.exit_code == 2 and "cannot write there" in res.output and not out.exists()


def test_a_store_that_is_not_sqlite_is_one_line_not_a_traceback(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "results.sqlite").write_bytes(b"SQLite format 3\x00 truncated")
    for args in (["report", str(run)], ["audit", "--out", str(run), "--n", "1", *SMALL]):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and "not a readable vbl-robust results store" in res.output, res.output
        assert res.exception is None or isinstance(res.exception, SystemExit)
    res = runner.invoke(app, ["report", str(run), "--out", str(run / "results.sqlite")])
    assert res.exit_code == 2 and "is a file" in res.output


def test_report_prints_the_summary_table_as_csv_and_json_with_exact_intervals(tmp_path):
    """`report RUN --format csv|json`: one row per method, box and budget; the interval is the exact one of the
    row's own counts; the job export carries each job's breach kind."""
    import io

    from vbl_robust.stats import Rate

    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "4", "--roll", "10", "--methods", "random,georobust",
                              "--max-evals", "8", "--no-landscape", "--no-report", "--workers", "1", "--csv",
                              str(tmp_path / "jobs.csv"), "--oracle", "--oracle-noise", "0.5", "--width", "320",
                              "--height", "320", "--quiet"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["report", str(out), "--format", "csv"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(io.StringIO(res.output)))
    assert [r["method"] for r in rows] == ["random", "georobust"]
    for r in rows:
        k, n = int(r["survivors"]), int(r["images"])
        ci = Rate(k, n).ci
        assert n == 4 and 0 < k < n and float(r["survival_pct"]) == pytest.approx(100 * k / n)
        assert (float(r["survival_ci_low"]), float(r["survival_ci_high"])) == pytest.approx((ci.low, ci.high))
        assert int(r["misleading"]) + int(r["flagged"]) == n - k
        assert (r["residual_bound"] != "") == (r["method"] == "random" and k > 0)
    res = runner.invoke(app, ["report", str(out), "--format", "json"])
    assert res.exit_code == 0 and [dict(d) for d in json.loads(res.output)] == [
        {**r, **{c: json.loads(r[c]) if r[c] != "" else None for c in r if c not in ("experiment", "method",
                                                                                      "box_label", "budget_label")}}
        for r in rows]
    jobs = list(csv.DictReader(open(tmp_path / "jobs.csv")))
    assert {j["breach_kind"] for j in jobs} <= {"safe", "flagged", "misleading"}
    assert sum(j["breach_kind"] != "safe" for j in jobs) == sum(4 - int(r["survivors"]) for r in rows)
    for bad, msg in ((["--format", "xml"], "choose html, md, csv or json"),
                     (["--format", "csv", "--out", str(tmp_path)], "--format csv prints the summary table")):
        res = runner.invoke(app, ["report", str(out), *bad])
        assert res.exit_code == 2 and msg in res.output, res.output


def test_a_store_refuses_a_detector_with_other_options(tmp_path):
    """Issue 48 item 2: the same model with another oracle noise (or design) is another detector: a second audit on
    the same --out is refused in one line instead of adding rows that the report would count twice."""
    out = tmp_path / "run"
    base = ["audit", "--out", str(out), "--n", "1", "--roll", "5", "--methods", "random", "--max-evals", "2",
            "--no-landscape", "--no-report", "--workers", "1", "--oracle", "--width", "96", "--height", "96", "-q"]
    assert runner.invoke(app, [*base, "--oracle-noise", "1"]).exit_code == 0
    res = runner.invoke(app, [*base, "--oracle-noise", "3"])
    assert res.exit_code == 2 and "holds results of detector" in res.output and "noise" in res.output, res.output
    from vbl_robust.store.core import ResultStore

    with ResultStore.open_existing(out) as st:
        assert st.count() == 1
    assert runner.invoke(app, [*base, "--oracle-noise", "1"]).exit_code == 0  # the same detector resumes


def test_a_full_disk_ends_the_run_in_one_line_and_keeps_the_stored_jobs(tmp_path, monkeypatch):
    """A disk full during a run (the store) or at its report was a traceback; now one line naming what failed,
    exit 1, and a rerun resumes from the jobs committed before."""
    import errno

    from vbl_robust.store.core import ResultStore

    out = tmp_path / "run"
    real_commit, commits = ResultStore.commit, []

    def full_after_one(self, rows):
        if commits:
            raise sqlite3.OperationalError("database or disk is full")
        commits.append(len(rows))
        return real_commit(self, rows)

    monkeypatch.setattr(ResultStore, "commit", full_after_one)
    # one image: its random job and its landscape grid, the second commit fails (no worker processes to start)
    args = ["audit", "--out", str(out), "--n", "1", "--max-evals", "5", "--methods", "random", *SMALL]
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert "error: the results store: database or disk is full (jobs stored before it are kept" in res.output
    with sqlite3.connect(out / "results.sqlite") as con:
        assert con.execute("SELECT count(*) FROM jobs").fetchone()[0] == 1
    monkeypatch.undo()

    import vbl_robust.report.build as build

    def no_space(path, data, **kw):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(build, "atomic_write", no_space)
    res = runner.invoke(app, args)
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert f"error: No space left on device: {out / 'report.html'}" in res.output
    assert "1 already done" in res.output  # resumed from the job committed before the disk filled
