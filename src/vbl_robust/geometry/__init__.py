"""Camera model, runway frame, LARD attitude conventions and geodesy (see :mod:`.camera` for conventions)."""

from .camera import (
    CORNER_NAMES,
    intrinsics,
    lard_attitude,
    lard_rotation,
    project,
    runway_corners,
    to_camera,
    world_to_cv,
)
from .geodesy import EARTH_RADIUS_M, RunwayFrame, runway_db_entry

__all__ = [
    "CORNER_NAMES",
    "EARTH_RADIUS_M",
    "RunwayFrame",
    "intrinsics",
    "lard_attitude",
    "lard_rotation",
    "project",
    "runway_corners",
    "runway_db_entry",
    "to_camera",
    "world_to_cv",
]
