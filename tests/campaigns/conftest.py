"""Fixtures for the campaign tests: a few small synthetic samples and the oracle detector (no network, fast)."""

from __future__ import annotations

import pytest
import torch

from vbl_robust.campaigns import DetectorSpec

torch.set_num_threads(1)

#: Small images keep the perturbations cheap; the oracle detector ignores the pixels' content.
SIZE = 128


@pytest.fixture(scope="session")
def small_samples():
    from vbl_robust.scenes import generate

    return generate(6, seed=3, width=SIZE, height=SIZE)


@pytest.fixture(scope="session")
def oracle():
    """Oracle with a fixed per-image corner error: a non-trivial, deterministic landscape with some breaches."""
    return DetectorSpec("oracle", options={"noise_px": 0.5, "fail_outside": True})
