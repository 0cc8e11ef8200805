"""The wheel works alone: `python -m build --wheel` gives a wheel with every package, every file the repository
tracks under src/vbl_robust (the shipped models, their default.json, the model card), the `vbl-robust` command,
and the version the package reports.

The wheel is built from a copy of the sources in a temporary directory (setuptools writes build/ and *.egg-info
beside its input, which must not race with other builds in the working tree), without build isolation: `build`
and setuptools come from the dev extra. A missing tool fails the test, never skips it.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "vbl_robust"


def _tracked_package_files() -> list[str]:
    """Files git tracks under src/vbl_robust, as wheel paths (vbl_robust/…)."""
    assert shutil.which("git"), "git is needed to list the tracked files"
    out = subprocess.run(["git", "ls-files", "-z", "src/vbl_robust"], cwd=ROOT, capture_output=True, check=True)
    files = [f for f in out.stdout.decode().split("\0") if f]
    assert files, "git ls-files found nothing under src/vbl_robust"
    return [str(Path(f).relative_to("src")) for f in files]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    assert importlib.util.find_spec("build") is not None, "the 'build' package is missing: pip install -e '.[dev]'"
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src_copy"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "src", src / "src",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
    out = tmp / "dist"
    proc = subprocess.run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(out), str(src)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"python -m build failed:\n{(proc.stdout + proc.stderr)[-4000:]}"
    wheels = list(out.glob("*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_name_and_version(wheel: Path) -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert wheel.name == f"vbl_robust-{version}-py3-none-any.whl"
    import vbl_robust

    assert vbl_robust.__version__ == version, "pyproject.toml and vbl_robust.__version__ disagree"
    with zipfile.ZipFile(wheel) as zf:
        metadata = zf.read(f"vbl_robust-{version}.dist-info/METADATA").decode()
    assert f"\nVersion: {version}\n" in metadata
    assert "Requires-Dist: torch==2.14.1" in metadata


def test_wheel_carries_the_models_and_every_package(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
    for needed in ("vbl_robust/models/runway_yolov8n_pose.pt", "vbl_robust/models/default.json",
                   "vbl_robust/models/MODEL_CARD.md", "vbl_robust/models/hardened/runway_yolov8n_pose.pt",
                   "vbl_robust/models/hardened/default.json", "vbl_robust/models/yolo26/default.json",
                   "vbl_robust/models/yolo26/runway_yolo26n_pose_pass2.pt"):
        assert needed in names, needed
    packages = sorted(str(p.parent.relative_to(PACKAGE.parent)) for p in PACKAGE.rglob("__init__.py"))
    assert len(packages) >= 12
    for package in packages:
        assert f"{package}/__init__.py" in names, f"package {package} missing from the wheel"
    missing = [f for f in _tracked_package_files() if f not in names]
    assert not missing, f"tracked files missing from the wheel (add them to package-data): {missing}"
    assert not [n for n in names if "__pycache__" in n or n.startswith(("tests/", "benchmarks/"))]


def test_wheel_shipped_model_is_the_repository_one(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as zf:
        for rel in ("models/runway_yolov8n_pose.pt", "models/default.json"):
            assert zf.read(f"vbl_robust/{rel}") == (PACKAGE / rel).read_bytes(), rel


def test_wheel_declares_the_command(wheel: Path) -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    with zipfile.ZipFile(wheel) as zf:
        entry_points = zf.read(f"vbl_robust-{version}.dist-info/entry_points.txt").decode()
    assert "[console_scripts]" in entry_points
    assert "vbl-robust = vbl_robust.cli:main" in entry_points
