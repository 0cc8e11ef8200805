"""LARD V2 approach envelopes and the sampling of approach poses from them.

Geometry (our reading of the LARD V2 generator, ``deel-ai/LARD`` branch LARD_V2, ``src/geo/geo_dataset.py``)
-----------------------------------------------------------------------------------------------------------
All positions are in the runway frame of :mod:`vbl_robust.geometry.camera` (origin at the landing threshold
point LTP, ``x`` along the runway, ``y`` left as seen from the approach, ``z`` up; metres), taken as the flat
local tangent plane at the LTP.

* ``distance_m`` ``d`` is the **horizontal** distance from the LTP to the camera (LARD walks ``d`` metres from the
  LTP along the ground).
* ``lateral_angle_deg`` ``α_h`` is the direction of that walk relative to the extended centreline, measured at
  the LTP: LARD walks along the true azimuth ``back_azimuth + α_h`` (clockwise from North), so ``α_h > 0`` puts
  the camera to the **left** of the centreline as seen from the approach (``y > 0``)::

      C_x = −d·cos α_h,   C_y = d·sin α_h

* ``vertical_angle_deg`` ``α_v`` (negative = descending path) fixes the height above the LTP with the glide path
  anchored at the aiming point **305 m past the LTP**: ``C_z = −tan(α_v)·(d + 305)``. As in LARD, the anchor
  distance is ``d + 305`` even off the centreline (the lateral offset is ignored for the height).
* Attitude: ``yaw`` (true heading) = runway azimuth + yaw offset, aeronautical pitch uniform in the envelope's
  range (LARD stores ``pitch = 90 + pitch``), roll uniform in ``±roll``; the camera is aligned with the body and
  is *not* aimed at the runway, so with large offsets the runway may leave the image.
* Every quantity is uniform in its range (the V2 default ODD file uses uniform distributions).

``require_visible=True`` (the default) mimics LARD V2, whose released images show the runway: the whole pose of
a sample (distance, path angles, attitude — envelope and runway kept) is redrawn until all four runway corners
are in front of the camera and inside the image with ``margin_px`` pixels to spare. The result is the envelope
distribution *conditioned on visibility*, so ranges still hold but the marginals are no longer exactly uniform.
With the LARD V2 camera (1024 × 1024, 60° FOV) the three envelopes are designed so that the runway is always in
view: measured on 9000 unconstrained draws, every corner stayed ≥ 58 px inside the image, so the redraw only
matters for narrower cameras or larger margins.

Determinism: sample ``i`` of ``sample_approaches(n, seed)`` is drawn from its own stream
``SeedSequence(seed, spawn_key=(i,))``, so it does not depend on ``n`` (``n=10`` is a prefix of ``n=100``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners, wrap_deg

from .airports import (  # realistic runway sizes, used when none is given
    RUNWAY_LENGTH_RANGE_M,
    RUNWAY_WIDTH_RANGE_M,
)

#: Distance from the LTP to the glide-path anchor (aiming point) along the runway, metres (LARD: 305 m = 1000 ft).
GLIDE_PATH_ANCHOR_M = 305.0

#: Pose draws per sample before ``require_visible`` gives up.
MAX_VISIBILITY_TRIES = 2000


@dataclass(frozen=True)
class Envelope:
    """One LARD V2 pose envelope; every range is ``(low, high)``, sampled uniformly.

    Attributes:
        name: ``"far"``, ``"medium"`` or ``"close"``.
        distance_m: horizontal distance from the LTP, metres.
        lateral_angle_deg: lateral path angle at the LTP, degrees (positive = left of the centreline).
        vertical_angle_deg: vertical path angle from the aiming point 305 m past the LTP, degrees (negative).
        yaw_offset_deg: true heading minus runway azimuth, degrees.
        pitch_deg: aeronautical pitch, degrees (negative = nose down; LARD stores ``90 + pitch``).
        roll_deg: roll, degrees (positive = right wing down).
    """

    name: str
    distance_m: tuple[float, float]
    lateral_angle_deg: tuple[float, float] = (-3.0, 3.0)
    vertical_angle_deg: tuple[float, float] = (-5.2, -1.8)
    yaw_offset_deg: tuple[float, float] = (-24.0, 24.0)
    pitch_deg: tuple[float, float] = (-15.0, 5.0)
    roll_deg: tuple[float, float] = (-30.0, 30.0)


#: The three LARD V2 default envelopes (``data/Lard_v2_Default_ODD.yaml``).
ENVELOPES: dict[str, Envelope] = {
    "far": Envelope("far", distance_m=(4500.0, 6000.0), roll_deg=(-30.0, 30.0)),
    "medium": Envelope("medium", distance_m=(2500.0, 4500.0), roll_deg=(-15.0, 15.0)),
    "close": Envelope("close", distance_m=(280.0, 2500.0), yaw_offset_deg=(-18.5, 18.5), roll_deg=(-10.0, 10.0)),
}


@dataclass(frozen=True, eq=False)
class Approach:
    """One sampled approach pose with its runway.

    Attributes:
        envelope: envelope name.
        position: (3,) camera position ``C`` in the runway frame, metres.
        R: (3, 3) camera → runway rotation (columns forward, left, up), ``lard_rotation(yaw, pitch, roll, az)``.
        yaw_deg: LARD yaw = true heading, degrees in [0, 360).
        pitch_deg: LARD stored pitch = 90 + aeronautical pitch, degrees.
        roll_deg: roll, degrees (positive = right wing down).
        distance_m: horizontal distance from the LTP, metres.
        lateral_angle_deg, vertical_angle_deg: path angles as sampled, degrees.
        yaw_offset_deg: heading minus runway azimuth, degrees.
        runway_length_m, runway_width_m: runway size, metres.
        runway_azimuth_deg: true azimuth of the runway (LTP → FPAP), degrees in [0, 360).
        tries: pose draws needed to satisfy ``require_visible`` (1 without it).
    """

    envelope: str
    position: np.ndarray
    R: np.ndarray
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    distance_m: float
    lateral_angle_deg: float
    vertical_angle_deg: float
    yaw_offset_deg: float
    runway_length_m: float
    runway_width_m: float
    runway_azimuth_deg: float
    tries: int = 1

    @property
    def corners_3d(self) -> np.ndarray:
        """(4, 3) runway corners TR, TL, BL, BR in the runway frame (flat runway)."""
        return runway_corners(self.runway_length_m, self.runway_width_m)

    @property
    def aero_pitch_deg(self) -> float:
        """Aeronautical pitch (negative = nose down), degrees."""
        return self.pitch_deg - 90.0

    @property
    def slant_distance_m(self) -> float:
        """Distance from the camera to the LTP, metres."""
        return float(np.linalg.norm(self.position))


def _check_range(name: str, lo_hi: tuple[float, float]) -> None:
    lo, hi = lo_hi
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"{name}: need finite low <= high, got {lo_hi}")


def resolve_envelopes(
    envelopes: Sequence[str | Envelope] | str, weights: Sequence[float] | None = None
) -> tuple[list[Envelope], np.ndarray]:
    """Envelope objects and normalised probabilities from names (case-insensitive) or :class:`Envelope` objects."""
    if isinstance(envelopes, str | Envelope):
        envelopes = [envelopes]
    envs: list[Envelope] = []
    for e in envelopes:
        if isinstance(e, Envelope):
            envs.append(e)
        elif isinstance(e, str) and e.lower() in ENVELOPES:
            envs.append(ENVELOPES[e.lower()])
        else:
            raise ValueError(f"envelopes: unknown envelope {e!r}; choose from {sorted(ENVELOPES)}")
    if not envs:
        raise ValueError("envelopes: need at least one envelope")
    if weights is None:
        p = np.full(len(envs), 1.0 / len(envs))
    else:
        p = np.asarray(weights, dtype=np.float64)
        if p.shape != (len(envs),) or not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
            raise ValueError(
                f"weights: need {len(envs)} finite non-negative numbers with a positive sum, got {weights!r}"
            )
        p = p / p.sum()
    return envs, p


def sample_stream(seed: int, i: int) -> np.random.SeedSequence:
    """Seed sequence of sample ``i`` of a dataset with ``seed`` (independent of the dataset size)."""
    if int(seed) < 0 or int(i) < 0:
        raise ValueError(f"seed and sample index must be non-negative, got seed={seed}, i={i}")
    return np.random.SeedSequence(int(seed), spawn_key=(int(i),))


def _draw_pose(rng: np.random.Generator, env: Envelope) -> tuple[float, ...]:
    u = lambda r: float(rng.uniform(r[0], r[1]))  # noqa: E731
    return (
        u(env.distance_m), u(env.lateral_angle_deg), u(env.vertical_angle_deg),
        u(env.yaw_offset_deg), u(env.pitch_deg), u(env.roll_deg),
    )


def approach_from_angles(
    envelope: str,
    distance_m: float,
    lateral_angle_deg: float,
    vertical_angle_deg: float,
    yaw_offset_deg: float,
    aero_pitch_deg: float,
    roll_deg: float,
    runway_length_m: float,
    runway_width_m: float,
    runway_azimuth_deg: float,
    tries: int = 1,
) -> Approach:
    """Build an :class:`Approach` from envelope coordinates (see the module docstring for the geometry)."""
    a_h, a_v = math.radians(lateral_angle_deg), math.radians(vertical_angle_deg)
    C = np.array([
        -distance_m * math.cos(a_h),
        distance_m * math.sin(a_h),
        -math.tan(a_v) * (distance_m + GLIDE_PATH_ANCHOR_M),
    ])
    yaw = (runway_azimuth_deg + yaw_offset_deg) % 360.0
    pitch_lard = 90.0 + aero_pitch_deg
    R = lard_rotation(yaw, pitch_lard, roll_deg, runway_azimuth_deg)
    return Approach(
        envelope=envelope, position=C, R=R, yaw_deg=yaw, pitch_deg=pitch_lard, roll_deg=roll_deg,
        distance_m=distance_m, lateral_angle_deg=lateral_angle_deg, vertical_angle_deg=vertical_angle_deg,
        yaw_offset_deg=wrap_deg(yaw_offset_deg), runway_length_m=runway_length_m, runway_width_m=runway_width_m,
        runway_azimuth_deg=runway_azimuth_deg % 360.0, tries=tries,
    )


def corners_visible(approach: Approach, K: np.ndarray, width: int, height: int, margin_px: float = 0.0) -> bool:
    """True when all four runway corners are in front of the camera and inside the image with a margin."""
    uv = project(approach.corners_3d, approach.R, approach.position, K)
    if not np.all(np.isfinite(uv)):
        return False
    u, v = uv[:, 0], uv[:, 1]
    return bool(
        np.all(u >= margin_px) and np.all(u <= width - 1 - margin_px)
        and np.all(v >= margin_px) and np.all(v <= height - 1 - margin_px)
    )


def fit_margin(margin_px: float, width: int, height: int) -> float:
    """The visibility margin used for a ``width`` × ``height`` image: ``margin_px``, at most a quarter of the
    smaller side less one pixel — so the smallest images (16 px) keep half their side for the runway; from 33 px
    up it is ``margin_px`` (8 px by default) unchanged."""
    return min(float(margin_px), (min(width, height) - 1) / 4.0)


def sample_approach(
    rng: np.random.Generator,
    envelope: Envelope,
    runway_length_m: float,
    runway_width_m: float,
    runway_azimuth_deg: float,
    *,
    require_visible: bool = True,
    K: np.ndarray | None = None,
    width: int = 1024,
    height: int = 1024,
    margin_px: float = 8.0,
) -> Approach:
    """Draw one approach to a given runway from ``envelope`` with ``rng``.

    With ``require_visible`` the pose is redrawn (at most :data:`MAX_VISIBILITY_TRIES` times, then
    ``RuntimeError``) until :func:`corners_visible` holds for intrinsics ``K`` (default: 60° FOV for
    ``width`` × ``height``) with the margin :func:`fit_margin` gives.
    """
    if K is None:
        K = intrinsics(width, height)
    margin_px = fit_margin(margin_px, width, height)
    for tries in range(1, MAX_VISIBILITY_TRIES + 1):
        d, a_h, a_v, dyaw, pitch, roll = _draw_pose(rng, envelope)
        app = approach_from_angles(
            envelope.name, d, a_h, a_v, dyaw, pitch, roll,
            runway_length_m, runway_width_m, runway_azimuth_deg, tries=tries,
        )
        if not require_visible or corners_visible(app, K, width, height, margin_px):
            return app
    raise RuntimeError(
        f"sample_approach: no pose of envelope {envelope.name!r} shows the whole runway "
        f"({runway_length_m:.0f} x {runway_width_m:.0f} m) in a {width}x{height} image with margin {margin_px} px "
        f"after {MAX_VISIBILITY_TRIES} tries; use a wider field of view, a smaller margin or require_visible=False"
    )


def sample_approaches(
    n: int,
    seed: int = 0,
    envelopes: Sequence[str | Envelope] | str = ("far", "medium", "close"),
    weights: Sequence[float] | None = None,
    *,
    require_visible: bool = True,
    width: int = 1024,
    height: int = 1024,
    fov_deg: float = 60.0,
    margin_px: float = 8.0,
    runway_length_range_m: tuple[float, float] = RUNWAY_LENGTH_RANGE_M,
    runway_width_range_m: tuple[float, float] = RUNWAY_WIDTH_RANGE_M,
) -> list[Approach]:
    """Sample ``n`` approach poses from the LARD V2 envelopes.

    Args:
        n: number of approaches (>= 0).
        seed: non-negative integer; sample ``i`` depends only on ``(seed, i)`` (prefix property).
        envelopes: envelope names (``"far"``, ``"medium"``, ``"close"``) or :class:`Envelope` objects.
        weights: relative probability of each envelope (default: equal).
        require_visible: redraw each pose until the whole runway is in the image (see module docstring).
        width, height, fov_deg: camera used for the visibility test (horizontal FOV, degrees).
        margin_px: inward margin of the visibility test, pixels.
        runway_length_range_m, runway_width_range_m: uniform ranges of the runway size; the runway azimuth
            is uniform in [0, 360).

    Returns:
        ``n`` :class:`Approach` objects.
    """
    if int(n) != n or n < 0:
        raise ValueError(f"n: need a non-negative integer, got {n!r}")
    _check_range("runway_length_range_m", runway_length_range_m)
    _check_range("runway_width_range_m", runway_width_range_m)
    if runway_length_range_m[0] <= 0 or runway_width_range_m[0] <= 0:
        raise ValueError("runway_length_range_m / runway_width_range_m: sizes must be positive")
    envs, p = resolve_envelopes(envelopes, weights)
    K = intrinsics(width, height, fov_deg)
    out = []
    for i in range(int(n)):
        rng = np.random.default_rng(sample_stream(seed, i))
        env = envs[int(rng.choice(len(envs), p=p))]
        length = float(rng.uniform(*runway_length_range_m))
        rwy_width = float(rng.uniform(*runway_width_range_m))
        azimuth = float(rng.uniform(0.0, 360.0))
        out.append(sample_approach(
            rng, env, length, rwy_width, azimuth, require_visible=require_visible,
            K=K, width=width, height=height, margin_px=margin_px,
        ))
    return out
