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

__all__ = [
    "CORNER_NAMES",
    "intrinsics",
    "lard_attitude",
    "lard_rotation",
    "project",
    "runway_corners",
    "to_camera",
    "world_to_cv",
]
