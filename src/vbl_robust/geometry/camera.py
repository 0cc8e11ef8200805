"""Camera model, runway frame and LARD V2 attitude conventions.

Conventions (used everywhere in this package)
---------------------------------------------
**Runway frame** (as the LARD V2 labeller): origin at the landing threshold point (LTP, midpoint of the two
threshold corners), ``x`` horizontal along the runway (LTP → FPAP), ``y`` to the left as seen from an aircraft
on the approach, ``z`` up. Metres. An approaching aircraft has ``x < 0``.

**Runway corners** are always in the order **TR, TL, BL, BR** (far-right, far-left, near-left, near-right as seen
from the approach; = runway DB corners A, B, C, D)::

    TR = (L, -W/2, z_far)   TL = (L, +W/2, z_far)   BL = (0, +W/2, 0)   BR = (0, -W/2, 0)

**Camera body axes**: ``forward, left, up``. The camera is aligned with the aircraft body (LARD V2). Its
orientation is the matrix ``R`` (3, 3) whose *columns* are the camera's forward, left and up axes expressed in the
runway frame (camera → runway). Starting aligned with the runway axes, the camera is rotated intrinsically

1. about ``z`` by ``runway_azimuth − yaw``   (yaw = true heading, degrees clockwise from North),
2. about the new ``y`` by ``90 − pitch_lard`` (LARD stores ``pitch_lard = 90 + aeronautical pitch``),
3. about the new ``x`` by ``roll``           (positive = right wing down),

so ``R = Rz(az − yaw) · Ry(90 − pitch_lard) · Rx(roll)``.

**Pixels** follow OpenCV: ``u`` to the right, ``v`` down, pixel *centres* at integer coordinates; the principal
point is ``(W/2, H/2)`` as in LARD. A camera-frame point ``(x_f, y_l, z_u)`` (forward, left, up) projects to
``u = cx − f·y_l/x_f``, ``v = cy − f·z_u/x_f``. The OpenCV camera axes are ``X = −left, Y = −up, Z = forward``.

**Intrinsics**: pinhole, square pixels, no distortion; LARD V2 images are 1024 × 1024 with a 60° FOV, so
``f = 512 / tan 30° ≈ 886.81 px``.
"""

from __future__ import annotations

import math

import numpy as np

#: OpenCV camera axes (X right, Y down, Z forward) from body camera axes (forward, left, up).
BODY_TO_CV = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])

CORNER_NAMES = ("TR", "TL", "BL", "BR")


def intrinsics(width: int = 1024, height: int = 1024, fov_deg: float = 60.0) -> np.ndarray:
    """Pinhole matrix K (3, 3) for a horizontal field of view ``fov_deg`` (square pixels, centre (W/2, H/2))."""
    if not (0.0 < fov_deg < 180.0):
        raise ValueError(f"intrinsics: fov_deg must be in (0, 180), got {fov_deg}")
    if width <= 0 or height <= 0:
        raise ValueError(f"intrinsics: width and height must be positive, got {width} x {height}")
    f = (width / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


def rot_x(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def lard_rotation(yaw_deg: float, pitch_lard_deg: float, roll_deg: float, runway_azimuth_deg: float) -> np.ndarray:
    """Camera → runway rotation ``R`` (3, 3) from LARD V2 attitude angles (see module conventions)."""
    return rot_z(runway_azimuth_deg - yaw_deg) @ rot_y(90.0 - pitch_lard_deg) @ rot_x(roll_deg)


def wrap_deg(a: float) -> float:
    """Wrap an angle to (−180, 180]."""
    w = math.fmod(a + 180.0, 360.0)
    if w <= 0.0:
        w += 360.0
    return w - 180.0


def lard_attitude(R: np.ndarray, runway_azimuth_deg: float) -> tuple[float, float, float]:
    """Inverse of :func:`lard_rotation`: ``(yaw_deg, pitch_lard_deg, roll_deg)``, yaw in [0, 360).

    Uses the Z-Y-X Euler decomposition ``R = Rz(a) Ry(b) Rx(c)``; unique for ``|b| < 90°``.
    """
    R = np.asarray(R, dtype=np.float64)
    b = math.degrees(math.asin(max(-1.0, min(1.0, -R[2, 0]))))
    a = math.degrees(math.atan2(R[1, 0], R[0, 0]))
    c = math.degrees(math.atan2(R[2, 1], R[2, 2]))
    yaw = (runway_azimuth_deg - a) % 360.0
    return yaw, 90.0 - b, c


def world_to_cv(R: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV extrinsics ``(R_cv (3, 3), t (3,))`` mapping runway points to OpenCV camera coordinates.

    ``X_cv = R_cv @ X_rwy + t``; the camera position is ``C = −R_cvᵀ t``.
    """
    R_cv = BODY_TO_CV @ np.asarray(R, dtype=np.float64).T
    t = -R_cv @ np.asarray(C, dtype=np.float64)
    return R_cv, t


def camera_position_from_cv(R_cv: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Camera position in the runway frame, ``C = −R_cvᵀ t``."""
    return -np.asarray(R_cv).T @ np.asarray(t).reshape(3)


def to_camera(points: np.ndarray, R: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Runway-frame points (N, 3) → camera body frame (N, 3) as (forward, left, up)."""
    return (np.asarray(points, dtype=np.float64) - np.asarray(C, dtype=np.float64)) @ np.asarray(R, dtype=np.float64)


def project(points: np.ndarray, R: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Project runway-frame points (N, 3) to float pixels (N, 2). Points behind the camera give NaN."""
    p = to_camera(points, R, C)
    fwd = p[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K[0, 2] - K[0, 0] * p[:, 1] / fwd
        v = K[1, 2] - K[1, 1] * p[:, 2] / fwd
    out = np.stack([u, v], axis=1)
    out[fwd <= 0] = np.nan
    return out


def runway_corners(length_m: float, width_m: float, far_end_height_m: float = 0.0) -> np.ndarray:
    """Corners (4, 3) of a straight runway in the runway frame, order TR, TL, BL, BR."""
    if length_m <= 0 or width_m <= 0:
        raise ValueError(f"runway_corners: length and width must be positive, got {length_m} x {width_m}")
    h = width_m / 2.0
    z = far_end_height_m
    return np.array([[length_m, -h, z], [length_m, h, z], [0.0, h, 0.0], [0.0, -h, 0.0]])
