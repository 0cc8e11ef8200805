"""The user paths run the way users run them: a LARD V2 directory (``audit --lard``, ``audit --sequences DIR``,
``reproduce --lard``) and Ray, with the **default** worker count, engine, device and detector — no environment
override of any of them (this module removes ``$VBL_ROBUST_WORKERS``). Only the size of the work is cut
(``--max-evals``, ``--methods``, image size).

The LARD directories are written by ``vbl-robust scenes`` (another user path)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import WORKERS_ENV, default_workers
from vbl_robust.cli import app
from vbl_robust.store.core import ResultStore

runner = CliRunner()


@pytest.fixture(autouse=True)
def _default_workers(monkeypatch):
    monkeypatch.delenv(WORKERS_ENV, raising=False)


@pytest.fixture(scope="module")
def lard_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("lard")
    res = runner.invoke(app, ["-q", "scenes", "--n", "3", "--width", "320", "--height", "320", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def lard_sequences(tmp_path_factory):
    out = tmp_path_factory.mktemp("lard_seq")
    res = runner.invoke(app, ["-q", "scenes", "--sequences", "2", "--frames", "2", "--width", "320", "--height",
                              "320", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _stored(out):
    with ResultStore(out / "results.sqlite", readonly=True) as st:
        return st.jobs(with_trace=False), st.runs()


def _check_complete(res, out, jobs_expected):
    assert res.exit_code == 0, res.output
    assert "unfinished" not in res.output and "Traceback" not in res.output, res.output
    rows, runs = _stored(out)
    assert len(rows) == jobs_expected and all(r.status.value == "done" for r in rows)
    assert [r.provenance.config["workers"] for r in runs] == [default_workers()]
    # what moves the numerics between machines is in the provenance (issue 45 item 8)
    machine = runs[0].provenance.config["machine"]
    assert machine["cpu"] and isinstance(machine["simd"], list) and machine["cores"] == default_workers()
    return rows


def test_a_lard_sample_pickles_with_its_image_loader(lard_dir):
    """What a worker process receives: the pickled sample loads the same pixels on the other side."""
    from vbl_robust.campaigns.samples import find_lard_files
    from vbl_robust.data.lard_read import read_lard

    sample = next(iter(read_lard(*find_lard_files(lard_dir))))
    copy = pickle.loads(pickle.dumps(sample))
    assert copy.id == sample.id and np.array_equal(copy.image, sample.image)


def test_audit_of_a_lard_directory_with_the_default_options(lard_dir, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--lard", str(lard_dir), "--out", str(out), "--max-evals", "4", "--quiet"])
    # the default count (20) exceeds the dataset: all 3 rows, 3 default methods each, plus the landscape grid
    rows = _check_complete(res, out, 3 * 3 + 1)
    assert {r.sample_id for r in rows} == {f"images/synth_s0_{i:06d}.png" for i in range(3)}
    assert (out / "report.html").exists()


def test_audit_of_a_lard_directory_refuses_more_images_than_it_has(lard_dir, tmp_path):
    res = runner.invoke(app, ["audit", "--lard", str(lard_dir), "--out", str(tmp_path / "r"), "--n", "4", "--quiet"])
    assert res.exit_code == 2 and "4 images asked for, the dataset has 3 usable rows" in res.output, res.output


def test_sequence_audit_of_a_lard_directory_with_the_default_options(lard_sequences, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--sequences", str(lard_sequences), "--out", str(out), "--max-evals", "3",
                              "--methods", "random", "--quiet"])
    rows = _check_complete(res, out, 2)
    assert len({r.sample_id for r in rows}) == 2


def test_reproduce_on_a_lard_directory_with_the_default_options(lard_dir, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["reproduce", "spatial-1d", "--lard", str(lard_dir), "--out", str(out), "--quiet",
                              "--methods", "random", "--max-evals", "3", "--grid-step", "0", "--no-landscape",
                              "--no-report"])
    # the paper's count (100) exceeds the dataset: all 3 rows, one job per roll box
    rows = _check_complete(res, out, 3 * 6)
    assert len({r.sample_id for r in rows}) == 3


@pytest.mark.slow
def test_audit_of_a_lard_directory_on_ray(lard_dir, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["audit", "--lard", str(lard_dir), "--out", str(out), "--executor", "ray",
                              "--max-evals", "3", "--methods", "random", "--no-landscape", "--quiet"])
    assert res.exit_code == 0, res.output
    rows, runs = _stored(out)
    assert len(rows) == 3 and all(r.status.value == "done" for r in rows)
    assert [r.provenance.executor for r in runs] == ["ray"]


def test_a_run_whose_images_cannot_be_read_is_refused_or_measures_nothing(lard_dir, tmp_path):
    """Images that cannot be read are refused before the run (exit 2, nothing stored); accepted with
    --allow-unmeasured, every job is not measured and no rate exists — a dash, never 0 % survival."""
    import json
    import shutil

    broken = tmp_path / "lard"
    shutil.copytree(lard_dir, broken)
    for png in (broken / "images").glob("*.png"):
        png.write_bytes(b"not a png")
    out = tmp_path / "run"
    args = ["audit", "--lard", str(broken), "--out", str(out), "--max-evals", "2", "--methods", "random",
            "--no-landscape", "--quiet"]
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "input unavailable: 3 of 3 image(s) cannot be used" in res.output, res.output
    assert not (out / "results.sqlite").exists()
    res = runner.invoke(app, [*args, "--allow-unmeasured"])
    assert res.exit_code == 0 and "3 of 3 jobs not measured" in res.output, res.output
    rows, _ = _stored(out)
    assert len(rows) == 3 and all(not r.measured and r.worst_m is None for r in rows)
    res = runner.invoke(app, ["report", str(out), "--format", "json", "--allow-unmeasured"])
    (line,) = json.loads(res.stdout)
    assert (line["images"], line["not_measured"], line["survival_pct"], line["survival_ci_low"]) == (0, 3, None, None)
