"""Sequence audits as campaigns: ``vbl-robust audit --sequences`` writes a results store, resumes, and ``zones``,
``report`` and ``--refine-zones`` work on it (oracle detectors, tiny images)."""

import csv
import json
import sqlite3

import numpy as np
import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.audit import audit_spec
from vbl_robust.campaigns.replay import zones_of_run
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.campaigns.samples import load_sequences
from vbl_robust.cli import app
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import roll_box
from vbl_robust.store.core import ResultStore

runner = CliRunner()
SMALL = ["--oracle", "--width", "96", "--height", "96", "--quiet", "--workers", "1"]
GATE = DetectorSpec("factory", "zones_helpers:RollGate")  # no detection where roll > 4°


def _rows(out):
    with ResultStore.open_existing(out) as store:
        return {r.key: r for r in store.jobs(with_points=True)}


def test_audit_sequences_writes_a_store_with_the_frames_and_resumes(tmp_path):
    out = tmp_path / "run"
    args = ["audit", "--sequences", "2", "--frames", "5", "--rate", "5", "--sustain", "2", "--roll", "5",
            "--methods", "grid,random", "--max-evals", "5", "--out", str(out), *SMALL]
    res = runner.invoke(app, [*args, "--csv", str(tmp_path / "jobs.csv")])
    assert res.exit_code == 0, res.output
    lines = list(csv.DictReader(open(tmp_path / "jobs.csv")))  # one line per job with its breach facts
    assert len(lines) == 4 and all(ln["longest_run_frames"] == "0" and ln["breach_start_m"] == "" for ln in lines)
    assert all(float(ln["nominal_sustained_m"]) < 1000 for ln in lines)
    rows = _rows(out)
    assert sorted((r.sample_id, r.method) for r in rows.values()) == [
        ("synth_q0_0000", "grid"), ("synth_q0_0000", "random"), ("synth_q0_0001", "grid"), ("synth_q0_0001", "random")]
    with ResultStore.open_existing(out) as store:
        spec = store.spec()
        samples = store.samples()
        run = store.runs()[-1]
    assert spec.settings.sustain == 2 and run.provenance.config["user"]["sequences"] == "2"
    assert samples["synth_q0_0000"].width == 96
    seq = next(iter(rows.values())).payload["sequence"]
    assert len(seq["frames"]["distance_m"]) == len(seq["worst"]["errors_m"]) == len(seq["nominal"]["reasons"]) == 5
    assert seq["worst"]["sustain"] == 2 and seq["frames"]["time_s"] == pytest.approx([0, 0.2, 0.4, 0.6, 0.8])
    for r in rows.values():  # the stored worst is the sustained error the payload recomputes at the worst θ
        assert r.worst_m == pytest.approx(r.payload["sequence"]["worst"]["sustained_m"], abs=1e-9)
    page = (out / "report.html").read_text()
    assert "Along the approach: errors sustained over 2 frame(s)" in page and "sequences;" in page
    assert (out / "figures" / "sequence_errors.png").stat().st_size > 1000

    again = runner.invoke(app, args)  # a rerun resumes: nothing new
    assert again.exit_code == 0 and "0 new jobs, 4 already done" in again.output, again.output
    gone = next(k for k, r in rows.items() if r.sample_id == "synth_q0_0001" and r.method == "random")
    with sqlite3.connect(out / "results.sqlite") as con:  # as if killed before that job was committed
        con.execute("DELETE FROM jobs WHERE key = ?", (gone,))
    res = runner.invoke(app, args)
    assert res.exit_code == 0 and "1 new jobs, 3 already done" in res.output, res.output
    redone = _rows(out)[gone]  # the same job again: the same points and worst case
    assert np.array_equal(redone.points.xs, rows[gone].points.xs) and redone.worst_m == rows[gone].worst_m


def test_zones_report_and_refinement_on_a_sequence_campaign(tmp_path):
    seqs, source = load_sequences("2", frames=4, rate_hz=2.0, seed=3, width=96, height=96)
    spec = audit_spec(roll_box(10.0), methods=("georobust", "random"), budget=Budget(max_evals=12, stop_at_breach=False),
                      seed=1, sustain=2)
    out = tmp_path / "run"
    with ResultStore(out / "results.sqlite") as store:
        run_campaign(spec, seqs, store, detector=GATE, dataset_source=source)
    rows = _rows(out)
    assert all(r.verdict == "breach" for r in rows.values())  # roll > 4° fails every frame: sustained 5000 m
    zones = [z for z in zones_of_run(out) if z.zones is not None]
    assert [z.method for z in zones] == ["georobust", "georobust"]
    assert all(z.zones.fractions["breached"] > 0 for z in zones)
    res = runner.invoke(app, ["zones", str(out), "--format", "csv"])
    assert res.exit_code == 0 and "breached" in res.output, res.output
    res = runner.invoke(app, ["report", str(out)])
    assert res.exit_code == 0, res.output
    page = (out / "report.html").read_text()
    section = page.split("Along the approach: errors sustained over 2 frame(s)")[1].split("<h2>")[0]
    assert section.count('<tr class="breach"><td class="l">synth_q3_000') == 2  # both sequences breach
    assert section.count("data:image/png;base64,") == 1
    res = runner.invoke(app, ["report", str(out), "--format", "md"])
    assert res.exit_code == 0 and "2 sequences measured by every method" in res.output, res.output

    from vbl_robust.campaigns.refine import refine_run

    path, refined = refine_run(out, seqs, GATE, 6, lipschitz=None)
    assert len(refined) == 2 and json.loads(path.read_text())["budget_per_job"] == 6


def test_scenes_sequences_then_audit_the_dataset_directory(tmp_path):
    data = tmp_path / "data"
    res = runner.invoke(app, ["scenes", "--sequences", "2", "--frames", "3", "--rate", "2", "--out", str(data),
                              "--width", "96", "--height", "96"])
    assert res.exit_code == 0, res.output
    assert "wrote 2 sequences of 3 frames at 2 Hz" in res.output
    header = (data / "metadata.csv").read_text().splitlines()[0]
    assert header.endswith("sequence_id;frame_index;time_s")
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--sequences", str(data), "--sustain", "3", "--roll", "5", "--methods", "random",
                              "--max-evals", "3", "--out", str(out), *SMALL])
    assert res.exit_code == 0, res.output
    with ResultStore.open_existing(out) as store:
        rows = store.jobs()
        run = store.runs()[-1]
        contents = {r[0] for r in store._con.execute("SELECT sample_id FROM contents")}
    assert [r.sample_id for r in rows] == ["synth_q0_0000", "synth_q0_0001"]
    assert len(rows[0].payload["sequence"]["frames"]["image"]) == 3 and run.provenance.dataset["source"]["kind"] == "lard sequences"
    assert len(contents) == 6  # every frame's file digest is recorded (a changed frame is refused on resume)


@pytest.mark.parametrize("args, message", [
    (["--sequences", "1", "--frames", "4", "--sustain", "5"], "sustain: need an integer k with 1 <= k <= 4"),
    (["--sequences", "nowhere"], "expected a number of sequences or a LARD V2 dataset directory"),
    (["--sequences", "1", "--lard", "."], "--lard and --sequences"),
    (["--sequences", "1", "--frames", "500", "--rate", "1"], "frames/rate_hz: 500 frames at 1 Hz"),
])
def test_sequence_audit_user_errors(tmp_path, args, message):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path / "run"), "--max-evals", "2", *args, *SMALL])
    assert res.exit_code == 2 and message in res.output, res.output
    assert not (tmp_path / "run").exists()  # refused before any work


def test_a_campaign_refuses_samples_of_the_other_kind(tmp_path):
    from vbl_robust.scenes.generate import generate

    seqs, _ = load_sequences("1", frames=2, rate_hz=1.0, seed=0, width=96, height=96)
    images = list(generate(1, seed=0, width=96, height=96))
    box, budget = roll_box(5.0), Budget(max_evals=2)
    for spec, samples, message in ((audit_spec(box, budget=budget, sustain=1), images, "needs approach sequences"),
                                   (audit_spec(box, budget=budget), seqs, "needs sustain")):
        with ResultStore(tmp_path / "s.sqlite") as store, pytest.raises(ValueError, match=message):
            run_campaign(spec, samples, store, detector=DetectorSpec.oracle(1.0))


def test_scenes_sequence_errors(tmp_path):
    res = runner.invoke(app, ["scenes", "--sequences", "1", "--frames", "50", "--rate", "1", "--speed", "500",
                              "--out", str(tmp_path), "--width", "96", "--height", "96"])
    assert res.exit_code == 2 and "frames/rate_hz" in res.output
