"""Runway views shared by the PnP tests (LARD V2 camera, runway frame of geometry.camera)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners


@dataclass
class View:
    corners_3d: np.ndarray  # (4, 3)
    K: np.ndarray  # (3, 3)
    R: np.ndarray  # (3, 3) camera -> runway
    position: np.ndarray  # (3,)
    points_2d: np.ndarray  # (4, 2) exact projections


def make_view(
    distance_m: float,
    lateral_deg: float = 0.0,
    glide_deg: float = 3.0,
    yaw_offset_deg: float = 0.0,
    pitch_deg: float = -3.0,
    roll_deg: float = 0.0,
    length_m: float = 3000.0,
    width_m: float = 45.0,
    azimuth_deg: float = 0.0,
) -> View:
    """Camera on an approach: horizontal distance from the LTP, glide path anchored 305 m past the LTP."""
    C = np.array([
        -distance_m * math.cos(math.radians(lateral_deg)),
        distance_m * math.sin(math.radians(lateral_deg)),
        math.tan(math.radians(glide_deg)) * (distance_m + 305.0),
    ])
    R = lard_rotation(azimuth_deg + yaw_offset_deg, 90.0 + pitch_deg, roll_deg, azimuth_deg)
    Z = runway_corners(length_m, width_m)
    K = intrinsics()
    return View(Z, K, R, C, project(Z, R, C, K))


@pytest.fixture
def view() -> Callable[..., View]:
    return make_view
