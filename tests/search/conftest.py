"""Objectives usable by every method: they accept numpy arrays and (for APGD) torch tensors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.space import ParameterBox


def _xp(x):
    return torch if isinstance(x, torch.Tensor) else np


def bumpy(x):
    """Smooth, multimodal, max 2.0 + small terms near (1.0, 10.3); works on numpy and torch (n, 2)."""
    xp = _xp(x)
    a, b = x[:, 0], x[:, 1]
    return 2.0 * xp.exp(-((a - 1.0) ** 2) - 4.0 * (b - 10.3) ** 2) + 0.3 * xp.sin(3.0 * a) * xp.cos(5.0 * b)


@pytest.fixture
def box2() -> ParameterBox:
    return ParameterBox({"roll_deg": (-3.0, 5.0), "contrast": (10.0, 11.0)})
