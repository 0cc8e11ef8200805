"""Fixtures for the campaign tests: a few small synthetic samples (no network, fast); the oracle detector is in
tests/conftest.py (the store, analysis and paper tests run campaigns with it too)."""

from __future__ import annotations

import pytest
import torch

torch.set_num_threads(1)

#: Small images keep the perturbations cheap; the oracle detector ignores the pixels' content.
SIZE = 128


@pytest.fixture(scope="session")
def small_samples():
    from vbl_robust.scenes.generate import generate

    return generate(6, seed=3, width=SIZE, height=SIZE)
