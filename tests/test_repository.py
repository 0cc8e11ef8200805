"""What git keeps (docs/conventions.md, *What the repository keeps*): code, docs, the shipped models and the paper's
packed stores. No weights outside ``src/vbl_robust/models/`` and ``tests/``, no raw results store, no HTML file
over 1 MB, and ``results/`` besides the paper's packed stores at most 10 MB.

Read from git's index (``git ls-files``: what the next commit holds, so a file staged by mistake fails here before
it is committed), sizes as the index holds them. Skipped only where there is no git checkout to read (an installed
wheel, an unpacked sdist); CI runs on a clean clone, where it runs.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Suffixes of model weights (an OpenVINO model is an ``.xml`` beside a ``.bin`` of the same name).
WEIGHT_SUFFIXES = (".pt", ".pth", ".onnx", ".safetensors", ".ckpt", ".bin")
#: Where weights may be tracked: the shipped models and the tests' fixtures.
WEIGHT_HOMES = ("src/vbl_robust/models/", "tests/")
#: The largest HTML file git keeps (a committed report shows its figures from files beside it).
HTML_MAX_BYTES = 1_000_000
#: What ``results/`` may hold besides the paper's packed stores.
RESULTS_MAX_BYTES = 10_000_000


def paper_store(path: str) -> bool:
    """Whether ``path`` is one of the paper's packed stores: ``results/paper/<experiment>/results.sqlite.xz``, or
    the same experiments run with another detector, ``results/paper/detectors/<label>/<experiment>/…``."""
    parts = PurePosixPath(path).parts
    if parts[:3] == ("results", "paper", "detectors"):
        parts = parts[:2] + parts[4:]
    return len(parts) == 4 and parts[:2] == ("results", "paper") and parts[3] == "results.sqlite.xz"


def weights_outside_homes(paths: Mapping[str, int]) -> list[str]:
    """The weight files among ``paths`` outside :data:`WEIGHT_HOMES`, an OpenVINO ``.xml`` with its ``.bin``
    included."""
    bins = {p.removesuffix(".bin") for p in paths if p.endswith(".bin")}
    return sorted(p for p in paths if not p.startswith(WEIGHT_HOMES) and (
        p.lower().endswith(WEIGHT_SUFFIXES) or (p.endswith(".xml") and p.removesuffix(".xml") in bins)))


def raw_stores(paths: Mapping[str, int]) -> list[str]:
    """The results stores among ``paths`` (``*.sqlite``, ``*.sqlite.xz``, ``*.db``) other than the paper's packed
    ones."""
    return sorted(p for p in paths if p.endswith((".sqlite", ".sqlite.xz", ".db")) and not paper_store(p))


def big_html(paths: Mapping[str, int]) -> list[str]:
    return sorted(f"{p} ({size / 1e6:.2f} MB)" for p, size in paths.items()
                  if p.lower().endswith((".html", ".htm")) and size > HTML_MAX_BYTES)


def results_bytes(paths: Mapping[str, int]) -> int:
    """Bytes under ``results/`` besides the paper's packed stores."""
    return sum(size for p, size in paths.items() if p.startswith("results/") and not paper_store(p))


def _tracked() -> dict[str, int]:
    """Every path in this checkout's git index with its size there; skips where there is none."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed: what a commit holds cannot be read")
    top = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=ROOT, capture_output=True, text=True)
    if top.returncode != 0 or Path(top.stdout.strip()).resolve() != ROOT:
        pytest.skip(f"{ROOT} is not a git checkout of the project (an installed wheel or an sdist): no index to read")
    listed = subprocess.run(["git", "ls-files", "-z", "-s"], cwd=ROOT, check=True, capture_output=True).stdout
    blobs = []
    for entry in filter(None, listed.split(b"\0")):
        meta, path = entry.split(b"\t", 1)
        mode, sha, _stage = meta.decode().split()
        if mode != "160000":  # a submodule is a commit, not a file
            blobs.append((sha, path.decode()))
    sizes = subprocess.run(["git", "cat-file", "--batch-check=%(objectsize)"], cwd=ROOT, check=True,
                           input="".join(f"{sha}\n" for sha, _ in blobs).encode(), capture_output=True).stdout.split()
    return {path: int(size) for (_, path), size in zip(blobs, sizes, strict=True)}


@pytest.fixture(scope="module")
def tracked() -> dict[str, int]:
    return _tracked()


def test_the_checks_catch_what_they_are_for():
    paths = {"src/vbl_robust/models/runway_yolov8n_pose.pt": 6_000_000, "tests/fixtures/tiny.onnx": 10_000,
             "results/detector_candidates/step_s.pt": 6_000_000, "train_runs/x/best.PTH": 1,
             "models/ov/model.xml": 100, "models/ov/model.bin": 5_000_000, "docs/layout.xml": 100,
             "results/paper/spatial-1d/results.sqlite.xz": 8_000_000, "results/harden/a/results.sqlite.xz": 700_000,
             "results/one-off/results.sqlite": 5_000_000, "results/paper/spatial-1d/report.html": 1_500_000,
             "results/paper/index.html": 20_000, "results/paper/nested/x/results.sqlite.xz": 1,
             "results/paper/detectors/u2/spatial-2d/results.sqlite.xz": 3_000_000,
             "results/paper/detectors/u2/nested/x/results.sqlite.xz": 2}
    assert weights_outside_homes(paths) == ["models/ov/model.bin", "models/ov/model.xml",
                                            "results/detector_candidates/step_s.pt", "train_runs/x/best.PTH"]
    assert raw_stores(paths) == ["results/harden/a/results.sqlite.xz", "results/one-off/results.sqlite",
                                 "results/paper/detectors/u2/nested/x/results.sqlite.xz",
                                 "results/paper/nested/x/results.sqlite.xz"]
    assert big_html(paths) == ["results/paper/spatial-1d/report.html (1.50 MB)"]
    assert results_bytes(paths) == 700_000 + 5_000_000 + 1_500_000 + 20_000 + 1 + 6_000_000 + 2


def test_no_weights_are_tracked_outside_the_shipped_models_and_the_tests(tracked):
    assert any(p.startswith("src/vbl_robust/models/") and p.endswith(".pt") for p in tracked), "read the index"
    assert weights_outside_homes(tracked) == [], (
        "weights outside src/vbl_robust/models/ and tests/ (a candidate's weights stay in train_runs/; its record "
        "says the command that rebuilds them): git rm --cached them")


def test_no_raw_results_store_is_tracked(tracked):
    assert raw_stores(tracked) == [], (
        "results stores besides the paper's packed ones (results/paper/*/results.sqlite.xz): keep a summary (Markdown, "
        "CSV, JSON) and the command that regenerates the store")


def test_no_tracked_html_file_is_over_1_mb(tracked):
    assert big_html(tracked) == [], "a committed report shows its figures from files (vbl-robust bundle)"


def test_results_besides_the_papers_packed_stores_stay_within_10_mb(tracked):
    size = results_bytes(tracked)
    assert 0 < size <= RESULTS_MAX_BYTES, f"results/ holds {size / 1e6:.1f} MB besides the paper's packed stores"
