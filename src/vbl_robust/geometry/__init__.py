"""Camera model, runway frame, LARD attitude conventions and geodesy (see :mod:`.camera` for conventions)."""

from .camera import intrinsics, lard_rotation, project
from .geodesy import RunwayFrame, runway_db_entry

__all__ = [
    "RunwayFrame",
    "intrinsics",
    "lard_rotation",
    "project",
    "runway_db_entry",
]
