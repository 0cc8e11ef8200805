"""Geodesy of LARD runways: geodetic (lat, lon, alt) ↔ the local runway frame of :mod:`.camera`.

Conventions
-----------
**Earth model**: the sphere of radius ``EARTH_RADIUS_M = 6 371 010 m`` used by the LARD runway databases for
their ECEF ``position`` fields (not WGS84). Latitudes/longitudes in degrees, altitudes in metres on the same
datum as the DB altitudes and the ``alt_cam`` column.

**Runway DB corners** ``A, B, C, D`` = ``TR, TL, BL, BR`` as seen from the approaching aircraft; ``C`` and ``D``
lie on the landing threshold.

**Runway frame** (:class:`RunwayFrame`): origin at the LTP, the ECEF midpoint of ``C`` and ``D`` (mapped back to
lat/lon/alt); FPAP = ECEF midpoint of ``A`` and ``B``. A geodetic point goes to ECEF on the sphere, then to the
local East-North-Up frame at the LTP, then is rotated about the vertical by the runway azimuth::

    x = e·sin(az) + n·cos(az)      (horizontal, along LTP → FPAP)
    y = −e·cos(az) + n·sin(az)     (horizontal, to the left)
    z = u                          (up at the LTP)

where ``az`` (:attr:`RunwayFrame.azimuth_deg`) is the bearing of the FPAP seen from the LTP, degrees clockwise
from true North in [0, 360). The plane ``z = 0`` is tangent to the sphere at the LTP, so a DB runway whose two
ends have the same altitude has its far end slightly below it (``−L²/2R``, 1.26 m for L = 4 km): the frame is
exact, the runway follows the Earth.

**Camera attitude of a LARD row** (:meth:`RunwayFrame.camera_rotation`): the LARD V2 labeller convention —
the camera starts aligned with the runway-frame axes and is rotated intrinsically by ``heading − yaw`` about z,
``90 − pitch`` about the new y and ``roll`` about the new x (:func:`.camera.lard_rotation`), where ``heading``
(:attr:`RunwayFrame.heading_deg`) is the runway's true azimuth as the labeller computes it: the forward azimuth
of the WGS84 geodesic from the lat/lon average of C, D to that of A, B. The attitude is thus relative to the
runway axes (level at the LTP), not to the local level at the aircraft.

Why this choice (measured on the published LARD V2 row of ``tests/fixtures/lard/``, CYEG runway 20 at 5.75 km;
labels are truncated, so a perfect model gives ``projection − label`` in [0, 1) px):

=========================================================  ==============================  ====================
convention                                                 projection − label (u; v) px    outside [0, 1)
=========================================================  ==============================  ====================
sphere frame, yaw relative to ``heading_deg`` (chosen)      u 0.10…0.89; v −0.42…0.51        0.42 px
sphere frame, yaw relative to the sphere ``azimuth_deg``    u −0.90…−0.12; v −0.45…0.48      0.90 px
sphere ECEF → NED at the aircraft → body → camera           u −0.32…0.46; v 0.37…1.30        0.32 / 0.30 px
LARD labeller itself (WGS84 geodesics, flat vertical)       u 0.08…0.87; v −0.09…0.63        0.09 px
=========================================================  ==============================  ====================

The sphere azimuth and the WGS84 azimuth differ by up to ``e²·cos²φ·sin(2az)/2`` (0.065° here, 1 px at f = 887
px), which is why the yaw reference matters. The positions stay on the sphere (the project's convention): the
labeller's own frame (WGS84 geodesic distances, ``z = alt − alt_LTP``) places that camera 8.4 m farther and
2.6 m higher (Earth curvature), a near-similarity that moves that row's corners by at most 0.33 px. (The
fixture's runway corners are rebuilt from LARD's FLSim runway list, see its README; the last table row is a
re-implementation of the labeller's computation on them.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pymap3d
from pymap3d.vincenty import vdist

from .camera import lard_attitude, lard_rotation, runway_corners

#: Radius of the sphere used by the LARD runway databases (metres).
EARTH_RADIUS_M = 6_371_010.0
#: The LARD sphere as a pymap3d ellipsoid.
SPHERE = pymap3d.Ellipsoid(EARTH_RADIUS_M, EARTH_RADIUS_M, name="LARD sphere", model="lard-sphere")

DB_CORNERS = ("A", "B", "C", "D")
_WGS84 = pymap3d.Ellipsoid.from_name("wgs84")


def geodetic_to_ecef(lat_deg, lon_deg, alt_m) -> np.ndarray:
    """ECEF coordinates (..., 3) in metres on the LARD sphere of geodetic points (degrees, metres)."""
    x, y, z = pymap3d.geodetic2ecef(
        np.asarray(lat_deg, dtype=np.float64), np.asarray(lon_deg, dtype=np.float64),
        np.asarray(alt_m, dtype=np.float64), ell=SPHERE,
    )
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_geodetic(xyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`geodetic_to_ecef`: ``(lat_deg, lon_deg, alt_m)`` arrays of shape (...)."""
    p = np.asarray(xyz, dtype=np.float64)
    r = np.linalg.norm(p, axis=-1)
    lat = np.degrees(np.arcsin(p[..., 2] / r))
    lon = np.degrees(np.arctan2(p[..., 1], p[..., 0]))
    return lat, lon, r - EARTH_RADIUS_M


def _enu_basis(lat_deg: float, lon_deg: float) -> np.ndarray:
    """(3, 3) matrix whose rows are the East, North, Up unit vectors in ECEF at (lat, lon) on the sphere."""
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    sla, cla, slo, clo = math.sin(la), math.cos(la), math.sin(lo), math.cos(lo)
    return np.array([[-slo, clo, 0.0], [-sla * clo, -sla * slo, cla], [cla * clo, cla * slo, sla]])


def _check_geodetic(name: str, lat: float, lon: float, alt: float) -> None:
    if not all(math.isfinite(float(v)) for v in (lat, lon, alt)):
        raise ValueError(f"{name}: lat/lon/alt must be finite, got ({lat}, {lon}, {alt})")
    if not -90.0 < float(lat) < 90.0:
        raise ValueError(f"{name}: latitude must be in (-90, 90) degrees, got {lat}")


@dataclass(frozen=True)
class RunwayFrame:
    """The local runway frame of one runway end (see module conventions).

    Attributes:
        ltp: (lat_deg, lon_deg, alt_m) of the landing threshold point, the frame origin.
        azimuth_deg: true bearing of the runway axis LTP → FPAP, degrees in [0, 360).
        heading_deg: true runway azimuth on WGS84 (the LARD labeller's), the reference of the camera yaw.
        corners_geodetic: (4, 3) DB corners A, B, C, D as (lat, lon, alt), or None when built from the LTP.
    """

    ltp: tuple[float, float, float]
    azimuth_deg: float
    heading_deg: float
    corners_geodetic: np.ndarray | None = None

    # ----------------------------------------------------------------------------------------- construction
    @classmethod
    def from_ltp(cls, lat_deg: float, lon_deg: float, alt_m: float, azimuth_deg: float) -> RunwayFrame:
        """Frame at a given LTP with a given runway azimuth (degrees clockwise from true North)."""
        _check_geodetic("RunwayFrame.from_ltp", lat_deg, lon_deg, alt_m)
        if not math.isfinite(float(azimuth_deg)):
            raise ValueError(f"RunwayFrame.from_ltp: azimuth_deg must be finite, got {azimuth_deg}")
        ltp = (float(lat_deg), float(lon_deg), float(alt_m))
        probe = cls(ltp, float(azimuth_deg) % 360.0, 0.0)
        far_lat, far_lon, _ = probe.to_geodetic(np.array([1000.0, 0.0, 0.0]))
        return cls(ltp, probe.azimuth_deg, _geodesic_azimuth(ltp[:2], (float(far_lat), float(far_lon))))

    @classmethod
    def from_corners(cls, corners) -> RunwayFrame:
        """Frame from the four DB corners.

        Args:
            corners: a runway entry of a LARD runway DB (``{"A": {"coordinate": {"latitude", "longitude",
                "altitude"}, ...}, "B": ..., "C": ..., "D": ...}``) or an array (4, 3) of (lat, lon, alt) in the
                order A, B, C, D (= TR, TL, BL, BR).
        """
        llh = _corners_array(corners)
        ecef = geodetic_to_ecef(llh[:, 0], llh[:, 1], llh[:, 2])
        lat0, lon0, alt0 = (float(v) for v in ecef_to_geodetic(0.5 * (ecef[2] + ecef[3])))
        fpap = 0.5 * (ecef[0] + ecef[1])
        e, n, _ = _enu_basis(lat0, lon0) @ (fpap - geodetic_to_ecef(lat0, lon0, alt0))
        if math.hypot(e, n) < 1e-6:
            raise ValueError("RunwayFrame.from_corners: LTP and FPAP coincide (degenerate runway corners)")
        az = math.degrees(math.atan2(e, n)) % 360.0
        heading = _geodesic_azimuth(_mean_lat_lon(llh[2], llh[3]), _mean_lat_lon(llh[0], llh[1]))
        return cls((lat0, lon0, alt0), az, heading, llh)

    # ----------------------------------------------------------------------------------------- mappings
    @property
    def _rotation(self) -> np.ndarray:
        """(3, 3) matrix mapping ECEF offsets from the LTP to runway-frame coordinates."""
        a = math.radians(self.azimuth_deg)
        s, c = math.sin(a), math.cos(a)
        enu_to_rwy = np.array([[s, c, 0.0], [-c, s, 0.0], [0.0, 0.0, 1.0]])
        return enu_to_rwy @ _enu_basis(self.ltp[0], self.ltp[1])

    @property
    def _origin_ecef(self) -> np.ndarray:
        return geodetic_to_ecef(*self.ltp)

    def to_runway(self, lat_deg, lon_deg, alt_m) -> np.ndarray:
        """Runway-frame coordinates (..., 3) in metres of geodetic points (degrees, metres)."""
        d = geodetic_to_ecef(lat_deg, lon_deg, alt_m) - self._origin_ecef
        return d @ self._rotation.T

    def to_geodetic(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inverse of :meth:`to_runway`: runway-frame points (..., 3) → ``(lat_deg, lon_deg, alt_m)``."""
        return ecef_to_geodetic(self.to_ecef(points))

    def to_ecef(self, points) -> np.ndarray:
        """Runway-frame points (..., 3) → ECEF (..., 3) on the LARD sphere."""
        return np.asarray(points, dtype=np.float64) @ self._rotation + self._origin_ecef

    @property
    def corners_3d(self) -> np.ndarray:
        """(4, 3) DB corners TR, TL, BL, BR in the runway frame (only for frames built from corners)."""
        if self.corners_geodetic is None:
            raise ValueError("RunwayFrame.corners_3d: frame was built from an LTP, not from runway corners")
        c = self.corners_geodetic
        return self.to_runway(c[:, 0], c[:, 1], c[:, 2])

    # ----------------------------------------------------------------------------------------- attitude
    def camera_rotation(self, yaw_deg: float, pitch_lard_deg: float, roll_deg: float) -> np.ndarray:
        """Camera → runway rotation (3, 3) from a LARD row's ``yaw, pitch, roll`` (module conventions)."""
        return lard_rotation(yaw_deg, pitch_lard_deg, roll_deg, self.heading_deg)

    def camera_attitude(self, R) -> tuple[float, float, float]:
        """Inverse of :meth:`camera_rotation`: LARD ``(yaw_deg in [0, 360), pitch_lard_deg, roll_deg)``."""
        return lard_attitude(R, self.heading_deg)


def _mean_lat_lon(p, q) -> tuple[float, float]:
    """Average of two (lat, lon, ...) points in degrees, as the LARD labeller does (safe across ±180°)."""
    dlon = (float(q[1]) - float(p[1]) + 180.0) % 360.0 - 180.0
    lon = (float(p[1]) + 0.5 * dlon + 180.0) % 360.0 - 180.0
    return 0.5 * (float(p[0]) + float(q[0])), lon


def _geodesic_azimuth(p, q) -> float:
    """Forward azimuth (degrees in [0, 360)) of the WGS84 geodesic from (lat, lon) ``p`` to ``q``."""
    _, az = vdist(p[0], p[1], q[0], q[1], ell=_WGS84)
    return float(az) % 360.0


def _corners_array(corners) -> np.ndarray:
    """(4, 3) float array of (lat, lon, alt) for corners A, B, C, D from a DB entry or an array."""
    if isinstance(corners, Mapping):
        rows = []
        for name in DB_CORNERS:
            try:
                c = corners[name]["coordinate"]
                rows.append([float(c["latitude"]), float(c["longitude"]), float(c["altitude"])])
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"runway corners: corner {name!r} lacks a numeric coordinate "
                                 f"latitude/longitude/altitude ({exc!r})") from None
        arr = np.array(rows)
    else:
        arr = np.asarray(corners, dtype=np.float64)
        if arr.shape != (4, 3):
            raise ValueError(f"runway corners: expected shape (4, 3) (lat, lon, alt of A..D), got {arr.shape}")
    for name, (lat, lon, alt) in zip(DB_CORNERS, arr, strict=True):
        _check_geodetic(f"runway corner {name}", lat, lon, alt)
    return arr


def runway_db_entry(
    ltp_lat: float,
    ltp_lon: float,
    ltp_alt: float,
    azimuth_deg: float,
    length_m: float,
    width_m: float,
    far_end_dz_m: float = 0.0,
) -> dict[str, dict[str, dict[str, float]]]:
    """A LARD runway DB entry (corners A..D) for a straight runway, the inverse of :meth:`RunwayFrame.from_corners`.

    The corners are :func:`.camera.runway_corners` ``(length_m, width_m, far_end_dz_m)`` in the runway frame at
    the LTP ``(ltp_lat, ltp_lon, ltp_alt)`` (degrees, metres) with bearing ``azimuth_deg`` (clockwise from true
    North), so ``far_end_dz_m`` is the height of the far end above the tangent plane of the LTP (not an altitude
    difference). Reading the entry back with :meth:`RunwayFrame.from_corners` gives the same LTP, azimuth and
    corners (to well below a millimetre).

    Returns:
        ``{"A": {"coordinate": {"latitude", "longitude", "altitude"}, "position": {"x", "y", "z"}}, ...}`` with
        ``position`` the ECEF coordinates on the LARD sphere (metres), as in the LARD V2 runway databases.
    """
    frame = RunwayFrame.from_ltp(ltp_lat, ltp_lon, ltp_alt, azimuth_deg)
    if not math.isfinite(float(far_end_dz_m)):
        raise ValueError(f"runway_db_entry: far_end_dz_m must be finite, got {far_end_dz_m}")
    pts = runway_corners(length_m, width_m, far_end_dz_m)
    ecef = frame.to_ecef(pts)
    lat, lon, alt = ecef_to_geodetic(ecef)
    return {
        name: {
            "coordinate": {"latitude": float(lat[i]), "longitude": float(lon[i]), "altitude": float(alt[i])},
            "position": {"x": float(ecef[i, 0]), "y": float(ecef[i, 1]), "z": float(ecef[i, 2])},
        }
        for i, name in enumerate(DB_CORNERS)
    }
