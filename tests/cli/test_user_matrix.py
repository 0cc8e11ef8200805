"""The user-path matrix: {the shipped model, a user's ``.pt`` with ``--trust-model``, a user's ONNX export} ×
{synthetic images, a LARD V2 directory (clean, and with one image missing), approach sequences}, run with the
options a user gets — default methods (georobust-av, random, APGD), workers, engine and device; only the size of
the work is cut (images, ``--max-evals``, the roll box, no landscape grid).

What it checks, per cell: the exit code, that no job is left not measured on sound input, and — with one image
missing — that the run is refused before it starts (exit 2, nothing stored), or, with ``--allow-unmeasured``, that
exactly that image's jobs are not measured (exit 0) and every other number equals the clean run's: a failure of the
tool is never a finding. ``make test`` runs the README's path (a user's ONNX export on LARD data); ``--full`` every
cell.
"""

from __future__ import annotations

import shutil

import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import WORKERS_ENV
from vbl_robust.cli import app
from vbl_robust.detect.shipped import DEFAULT_MODEL
from vbl_robust.store.core import ResultStore

runner = CliRunner()
#: The work cut to test size (no user-path option: methods, workers, engine and device stay the defaults).
SIZE = ["--max-evals", "4", "--roll", "5", "--no-landscape", "--quiet"]
METHODS = {"georobust-av", "random", "apgd"}
MODELS = ("shipped", "user-pt", "user-onnx")
DATA = ("synthetic", "lard", "sequences")
#: The cell ``make test`` runs: the README's "your model and your data" path (a user's ONNX export on LARD data, its
#: broken variants included); ``--full`` runs all nine. The shipped model on synthetic images, LARD data and
#: sequences with the default options is ``make test``'s elsewhere too (tests/cli/test_user_paths.py, the demo).
SMALL = {("user-onnx", "lard")}


@pytest.fixture(autouse=True)
def _default_workers(monkeypatch):
    monkeypatch.delenv(WORKERS_ENV, raising=False)


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """The model options of each row: none (the shipped model), a copy of it as a user's ``.pt``, and its ONNX
    export the way a user makes one (``yolo export format=onnx imgsz=320``)."""
    from vbl_robust.detect.offline import import_ultralytics

    import_ultralytics()
    from ultralytics import YOLO

    work = tmp_path_factory.mktemp("models")
    shutil.copyfile(DEFAULT_MODEL, work / "my_model.pt")
    YOLO(str(work / "my_model.pt"), task="pose").export(format="onnx", imgsz=320, verbose=False)
    assert (work / "my_model.onnx").is_file()
    return {"shipped": [], "user-pt": ["--model", str(work / "my_model.pt"), "--trust-model"],
            "user-onnx": ["--model", str(work / "my_model.onnx")]}


@pytest.fixture(scope="module")
def lard_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("lard")
    res = runner.invoke(app, ["-q", "scenes", "--n", "2", "--seed", "3", "--width", "320", "--height", "320",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def lard_one_missing(lard_dir, tmp_path_factory):
    """The same directory with its second image deleted (its CSV row kept)."""
    out = tmp_path_factory.mktemp("lard_missing") / "lard"
    shutil.copytree(lard_dir, out)
    (out / "images" / "synth_s3_000001.png").unlink()
    return out


DATA_ARGS = {"synthetic": lambda d: ["--n", "2", "--width", "320", "--height", "320"],
             "lard": lambda d: ["--lard", str(d["lard"])],
             "sequences": lambda d: ["--sequences", "1", "--frames", "2", "--width", "320", "--height", "320"]}


def _rows(out):
    with ResultStore(out / "results.sqlite", readonly=True) as st:
        return st.jobs(with_trace=False)


def _numbers(rows):
    """What a rate is made of: per (image, method) the worst error and the verdict of each measured job."""
    return {(r.sample_id, r.method): (r.worst_m, r.verdict) for r in rows if r.measured}


@pytest.mark.slow
@pytest.mark.parametrize("data", DATA)
@pytest.mark.parametrize("model", MODELS)
def test_user_path_matrix(model, data, models, lard_dir, lard_one_missing, tmp_path, full):
    if not full and (model, data) not in SMALL:
        pytest.skip("runs under --full")
    paths = {"lard": lard_dir}
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", *models[model], *DATA_ARGS[data](paths), "--out", str(out), *SIZE])
    assert res.exit_code == 0, res.output
    rows = _rows(out)
    units = 1 if data == "sequences" else 2
    assert len(rows) == units * len(METHODS) and {r.method for r in rows} == METHODS
    assert all(r.measured for r in rows), [r.reason for r in rows if not r.measured]  # APGD runs on every model
    if data != "lard":
        return

    # one image missing: refused before the run, in one line, nothing stored
    broken = tmp_path / "broken"
    res = runner.invoke(app, ["audit", *models[model], "--lard", str(lard_one_missing), "--out", str(broken),
                              *SIZE])
    assert res.exit_code == 2, res.output
    assert "input unavailable: 1 of 2 image(s) cannot be used: images/synth_s3_000001.png: image file not found" \
        in res.output and "nothing was run or stored" in res.output
    assert not (broken / "results.sqlite").exists()

    # accepted: the missing image's jobs are not measured, the other image's numbers are the clean run's
    res = runner.invoke(app, ["audit", *models[model], "--lard", str(lard_one_missing), "--out", str(broken),
                              "--allow-unmeasured", *SIZE])
    assert res.exit_code == 0, res.output
    assert "3 of 6 jobs not measured" in res.output and "Traceback" not in res.output
    kept = _rows(broken)
    missing = [r for r in kept if not r.measured]
    assert {r.sample_id for r in missing} == {"images/synth_s3_000001.png"} and len(missing) == len(METHODS)
    assert all(r.reason.startswith("input unavailable: images/synth_s3_000001.png: ") for r in missing)
    assert all(r.worst_m is None for r in missing)  # never the 5000 m penalty
    clean = _numbers(rows)
    assert _numbers(kept) == {k: v for k, v in clean.items() if k[0] != "images/synth_s3_000001.png"}
    # the summary table counts the image for no method: n is the measured image alone
    res = runner.invoke(app, ["report", str(broken), "--format", "json"])
    assert res.exit_code == 1 and "3 of 6 jobs not measured" in res.stderr
    res = runner.invoke(app, ["report", str(broken), "--format", "json", "--allow-unmeasured"])
    assert res.exit_code == 0
    import json

    lines = json.loads(res.stdout)
    assert {ln["method"] for ln in lines} == METHODS
    assert all(ln["images"] == 1 and ln["not_measured"] == 1 for ln in lines)


def test_a_method_the_model_cannot_run_is_refused_before_the_run(models, lard_dir, tmp_path, monkeypatch):
    """An ONNX model whose torch twin cannot be made gives no gradient: APGD (a default method) is refused before the
    run, in one line naming the black-box methods (exit 2, nothing stored) — never 5000 m per image."""
    from vbl_robust.detect import onnx_twin

    def broken(path):
        raise ValueError("onnx2pytorch cannot convert the graph (NotImplementedError: Split v18)")

    from vbl_robust.campaigns import work

    monkeypatch.setattr(onnx_twin, "convert_onnx", broken)
    monkeypatch.setattr(work, "_DETECTORS", {})  # built afresh in this process, as in a new command
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", *models["user-onnx"], "--lard", str(lard_dir), "--out", str(out), *SIZE])
    assert res.exit_code == 2, res.output
    line = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(line) == 1 and line[0].startswith("error: --methods apgd: method unfit — the detector ")
    assert "Split v18" in line[0] and "use a black-box method instead: " in line[0] and "random" in line[0]
    assert not (out / "results.sqlite").exists()
    # the jobs in this process, where the twin cannot be made (worker processes would import the real converter)
    res = runner.invoke(app, ["audit", *models["user-onnx"], "--lard", str(lard_dir), "--out", str(out), *SIZE,
                              "--methods", "georobust-av,random", "--workers", "1"])
    assert res.exit_code == 0, res.output
    assert all(r.measured for r in _rows(out))
