"""Shared test configuration.

``make test`` runs everything, slow end-to-end checks included, in a small form; ``make test-full`` passes
``--full`` so tests that use the ``full`` fixture run at their full size.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Never let ultralytics or any library reach the network from the tests.
os.environ.setdefault("YOLO_OFFLINE", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# No global override of the worker count, engine or device: tests run what users get by default
# (tests/cli/test_user_paths.py); a test that needs the jobs in its own process says --workers 1.


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--full", action="store_true", default=False, help="run slow end-to-end checks at full size")


@pytest.fixture(scope="session")
def full(request: pytest.FixtureRequest) -> bool:
    """True under ``--full``: slow tests use their full-size parameters."""
    return bool(request.config.getoption("--full"))


@pytest.fixture(scope="session")
def script():
    """Load a repository script (``benchmarks/…`` or ``tools/…``) as a module: ``script("tools/x.py")``. Its own
    folder goes on ``sys.path`` first, as when it runs."""
    def load(rel: str):
        path = ROOT / rel
        if str(path.parent) not in sys.path:
            sys.path.insert(0, str(path.parent))
        spec = importlib.util.spec_from_file_location(path.stem, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    return load


@pytest.fixture(scope="session")
def oracle():
    """Oracle with a fixed per-image corner error: a non-trivial, deterministic landscape with some breaches (the
    detector of the tests that run small campaigns)."""
    from vbl_robust.campaigns.provenance import DetectorSpec

    return DetectorSpec("oracle", options={"noise_px": 0.5, "fail_outside": True})
