"""``vbl-robust scenes --sequences`` and ``vbl-robust audit --sequences`` on tiny inputs (oracle detector)."""

import csv
import json

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()
SMALL = ["--oracle", "--width", "96", "--height", "96", "--quiet"]


def test_audit_generated_sequences_writes_json_csv_and_figure(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--sequences", "2", "--frames", "5", "--rate", "5", "--sustain", "2",
                              "--roll", "5", "--methods", "grid,random", "--max-evals", "5", "--out", str(out), *SMALL])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(open(out / "sequences.csv")))
    assert [r["sequence_id"] for r in rows] == ["synth_q0_0000", "synth_q0_0001"]
    assert {"worst_sustained_m", "worst_roll_deg", "longest_run_frames", "breach_start_m", "verdict"} <= set(rows[0])
    summary = json.loads((out / "sequences.json").read_text())
    assert summary["sustain"] == 2 and summary["detector"]["kind"] == "oracle"
    seq = summary["sequences"][0]
    assert len(seq["worst"]["errors_m"]) == len(seq["distances_m"]) == 5
    assert [m["method"] for m in seq["methods"]] == ["grid", "random"]
    frames = list(csv.DictReader(open(out / "sequence_frames.csv")))
    assert len(frames) == 10 and {"distance_m", "nominal_error_m", "worst_error_m"} <= set(frames[0])
    assert (out / "figures" / "sequence_errors.png").stat().st_size > 1000


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
    rows = list(csv.DictReader(open(out / "sequences.csv")))
    assert [r["sequence_id"] for r in rows] == ["synth_q0_0000", "synth_q0_0001"] and rows[0]["frames"] == "3"


@pytest.mark.parametrize("args, message", [
    (["--sequences", "1", "--frames", "4", "--sustain", "5"], "sustain: need an integer k with 1 <= k <= 4"),
    (["--sequences", "nowhere"], "expected a number of sequences or a LARD V2 dataset directory"),
    (["--sequences", "1", "--lipschitz", "3"], "--lipschitz do(es) not apply to a sequence audit"),
    (["--sequences", "1", "--frames", "500", "--rate", "1"], "frames/rate_hz: 500 frames at 1 Hz"),
])
def test_sequence_audit_user_errors(tmp_path, args, message):
    res = runner.invoke(app, ["audit", "--out", str(tmp_path), "--max-evals", "2", *args, *SMALL])
    assert res.exit_code == 2 and message in res.output, res.output


def test_scenes_sequence_errors(tmp_path):
    res = runner.invoke(app, ["scenes", "--sequences", "1", "--frames", "50", "--rate", "1", "--speed", "500",
                              "--out", str(tmp_path), "--width", "96", "--height", "96"])
    assert res.exit_code == 2 and "frames/rate_hz" in res.output
