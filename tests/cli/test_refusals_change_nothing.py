"""A refusal changes nothing: a campaign command refused (a bad option value of each kind, a method unfit for the
detector, a missing or changed image, another campaign's settings into an existing ``--out``, a store in use, …)
exits 2 and leaves every run directory byte-identical — no rewritten ``config.yaml``, no store holding only a
campaign, no new directory — so ``--config RUN/config.yaml`` still repeats the run."""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()

AUDIT = ["audit", "-q", "--lard", "{lard}", "--oracle", "--methods", "random", "--max-evals", "4", "--no-landscape",
         "--workers", "1", "--no-report", "--out", "{run}"]
RISK = ["risk", "-q", "--lard", "{lard}", "--oracle", "--methods", "mc", "--max-evals", "8", "--guide-evals", "4", "--workers", "1",
        "--no-report", "--out", "{risk}"]


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    """A LARD directory of two images, an audit run and a risk run on it (done, exit 0)."""
    root = tmp_path_factory.mktemp("made")
    here = os.getcwd()
    os.chdir(root)  # the runs name their paths relative to it, as a user in their project directory does
    try:
        res = runner.invoke(app, ["-q", "scenes", "--n", "2", "--width", "96", "--height", "96", "--out", "lard"])
        assert res.exit_code == 0, res.output
        for args in (AUDIT, RISK):
            res = runner.invoke(app, _fill(args))
            assert res.exit_code == 0, res.output
    finally:
        os.chdir(here)
    return root


def _fill(args: list[str]) -> list[str]:
    names = {"lard": "lard", "run": "RUN", "risk": "RISK", "missing": "nothing-here"}
    return [a.format(**names) for a in args]


def snapshot(root: Path) -> dict[str, tuple[str, int]]:
    """Every file and directory under ``root``: its bytes' SHA-256 (directories: "dir") and its mtime (ns)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.stat()
            digest = "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
            out[str(p.relative_to(root))] = (digest, st.st_mtime_ns)
    return out


@pytest.fixture
def work(made, tmp_path, monkeypatch) -> Path:
    """A copy of the runs (mtimes kept) for one refusal."""
    root = tmp_path / "w"
    shutil.copytree(made, root, copy_function=shutil.copy2)
    monkeypatch.chdir(root)
    return root


def _oracle_without_gradient(monkeypatch, root):
    from vbl_robust.campaigns import work
    from vbl_robust.detect.oracle import OracleDetector

    monkeypatch.setattr(OracleDetector, "differentiable", False)
    monkeypatch.setattr(work, "_DETECTORS", {})


def _remove_an_image(monkeypatch, root):
    next((root / "lard" / "images").iterdir()).unlink()


def _change_an_image(monkeypatch, root):
    """Other pixels of the same size under the same name (the stored jobs were computed on the old ones)."""
    import numpy as np
    from PIL import Image

    path = sorted((root / "lard" / "images").iterdir())[0]
    pixels = np.asarray(Image.open(path)).copy()
    pixels[:8, :8] = 255 - pixels[:8, :8]
    Image.fromarray(pixels).save(path)


#: Locks a case holds while its command runs.
_HELD: list = []


def _hold_the_store(monkeypatch, root):
    """Another run writing the store (its writer lock held)."""
    from vbl_robust.store.lock import WriterLock

    _HELD.append(WriterLock(root / "RUN" / "results.sqlite").acquire())


def _bad_config(monkeypatch, root):
    (root / "bad.yaml").write_text("seed: true\n")


#: (id, arguments, what to do first, text of the one error line)
CASES = [
    ("audit-bad-roll", AUDIT + ["--roll", "abc"], None, "--roll"),
    ("audit-roll-trailing-comma", AUDIT + ["--roll", "5,"], None, "--roll"),
    ("audit-noise-without-oracle", [a for a in AUDIT if a != "--oracle"] + ["--oracle-noise", "3"], None,
     "--oracle-noise"),
    ("audit-method-unfit", AUDIT + ["--methods", "apgd"], _oracle_without_gradient,
     "method unfit"),
    ("audit-missing-image", AUDIT, _remove_an_image, "input unavailable"),
    ("audit-changed-image", AUDIT, _change_an_image, "changed since their results were stored"),
    ("audit-other-settings", AUDIT + ["--max-evals", "5"], None, "with other settings"),
    ("audit-other-seed", AUDIT + ["--seed", "1"], None, "with other settings"),
    ("audit-other-detector", AUDIT + ["--oracle-noise", "2"], None, "holds results of detector"),
    ("audit-store-in-use", AUDIT, _hold_the_store, "in use by PID"),
    ("audit-bad-target", AUDIT + ["--target", "bogus"], None, "--target"),
    ("audit-bad-workers", AUDIT + ["--workers", "-1"], None, "--workers"),
    ("audit-bad-csv", AUDIT + ["--csv", "{run}/x.txt"], None, "--csv"),
    ("audit-frames-without-sequences", AUDIT + ["--frames", "3"], None, "--frames"),
    ("audit-bad-lipschitz", AUDIT + ["--lipschitz", "-1"], None, "--lipschitz"),
    ("audit-bad-method-option", AUDIT + ["--method-option", "random.nothing=1"], None, "--method-option"),
    ("audit-bad-executor", AUDIT + ["--executor", "bogus"], None, "--executor"),
    ("audit-address-without-ray", AUDIT + ["--address", "localhost:1"], None, "--address"),
    ("audit-bad-perturb", AUDIT + ["--perturb", "bogus"], None, "--perturb"),
    ("audit-bad-contrast", AUDIT + ["--contrast", "2,1"], None, "--contrast"),
    ("audit-sigma-without-sigma", AUDIT + ["--monitor-sigma", "5"], None, "--monitor-sigma"),
    ("audit-bad-clock", AUDIT + ["--clock", "bogus"], None, "--clock"),
    ("audit-no-budget", AUDIT + ["--max-evals", "0"], None, "max_seconds"),
    ("audit-missing-model", [a for a in AUDIT if a != "--oracle"] + ["--model", "{missing}.onnx"], None,
     "model file not found"),
    ("audit-bad-config", AUDIT + ["--config", "bad.yaml"], _bad_config, "--config"),
    ("audit-missing-lard", AUDIT + ["--lard", "{missing}"], None, "nothing-here"),
    ("risk-bad-dist", RISK + ["--dist", "roll_deg=normal:0,-1"], None, "--dist"),
    ("risk-unknown-dist", RISK + ["--dist", "bogus=uniform"], None, "--dist"),
    ("risk-contradictory-dist", RISK + ["--dist", "roll_deg=uniform", "--dist", "roll_deg=normal:0,1"], None,
     "--dist"),
    ("risk-bad-methods", RISK + ["--methods", "bogus"], None, "--methods"),
    ("risk-bad-tau", RISK + ["--tau", "nan"], None, "--tau"),
    ("risk-noise-without-oracle", [a for a in RISK if a != "--oracle"] + ["--oracle-noise", "3"], None,
     "--oracle-noise"),
    ("risk-other-settings", RISK + ["--max-evals", "9"], None, "with other settings"),
    ("risk-missing-image", RISK, _remove_an_image, "input unavailable"),
    ("risk-into-the-audit-run", RISK[:-1] + ["{run}"], None, "with other settings"),
    ("reproduce-unknown", ["reproduce", "bogus", "--out", "{run}"], None, "bogus"),
    ("reproduce-noise-without-oracle", ["reproduce", "spatial-1d", "--out", "{run}", "--oracle-noise", "3"], None,
     "--oracle-noise"),
    ("reproduce-bad-budgets", ["reproduce", "runtime-1d", "--out", "{run}", "--eval-budgets", "x"], None,
     "--eval-budgets"),
    ("reproduce-bad-method-option", ["reproduce", "spatial-1d", "--out", "{run}", "--method-option", "apgd.x=1"],
     None, "--method-option"),
    ("reproduce-missing-bundle", ["reproduce", "spatial-1d", "--out", "{run}", "--resume-from", "{missing}"], None,
     "--resume-from"),
    ("reproduce-into-the-audit-run", ["reproduce", "spatial-1d", "-q", "--out", "{run}", "--images", "2", "--lard",
                                      "{lard}", "--oracle", "--workers", "1", "--no-report", "--no-landscape",
                                      "--max-evals", "4", "--grid-step", "0"], None, "with other settings"),
    ("truth-bad-counts", ["truth", "{run}", "--counts", "x"], None, "--counts"),
    ("truth-missing-run", ["truth", "{missing}", "--counts", "3"], None, "no results store"),
    ("truth-of-a-risk-run", ["truth", "{risk}", "--counts", "3"], None, "error"),
    ("truth-bad-workers", ["truth", "{run}", "--counts", "3", "--workers", "-1"], None, "--workers"),
]


@pytest.mark.parametrize("args, before, message", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_refused_command_exits_2_and_changes_nothing(work, monkeypatch, args, before, message):
    if before is not None:
        before(monkeypatch, work)
    kept = snapshot(work)
    config = (work / "RUN" / "config.yaml").read_bytes()
    try:
        res = runner.invoke(app, _fill(args))
    finally:
        while _HELD:
            _HELD.pop().release()
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and message in res.output, res.output
    errors = [ln for ln in res.output.splitlines() if ln.lower().startswith("error")]
    assert len(errors) == 1, res.output
    now = snapshot(work)
    changed = sorted(k for k in set(kept) | set(now) if kept.get(k) != now.get(k))
    assert not changed, f"changed by a refusal: {changed}"
    assert (work / "RUN" / "config.yaml").read_bytes() == config


def test_the_kept_configuration_still_repeats_the_run_after_a_refusal(work):
    """The issue's case: ``audit … --oracle-noise 3 --out RUN`` refused, then ``audit --config RUN/config.yaml``
    resumes the run (nothing new to run)."""
    refused = runner.invoke(app, _fill([a for a in AUDIT if a != "--oracle"] + ["--oracle-noise", "3"]))
    assert refused.exit_code == 2, refused.output
    again = runner.invoke(app, ["-q", "audit", "--config", "RUN/config.yaml"])
    assert again.exit_code == 0 and "0 new jobs, 2 already done" in again.output, again.output
