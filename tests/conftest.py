"""Shared test configuration.

``make test`` runs everything, slow end-to-end checks included, in a small form; ``make test-full`` passes
``--full`` so tests that use the ``full`` fixture run at their full size.
"""

from __future__ import annotations

import os

import pytest

# Never let ultralytics or any library reach the network from the tests.
os.environ.setdefault("YOLO_OFFLINE", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--full", action="store_true", default=False, help="run slow end-to-end checks at full size")


@pytest.fixture(scope="session")
def full(request: pytest.FixtureRequest) -> bool:
    """True under ``--full``: slow tests use their full-size parameters."""
    return bool(request.config.getoption("--full"))
