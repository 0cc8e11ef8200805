"""Geodesy on the LARD sphere: round trips, agreement with pymap3d, DB entries, reprojection invariance."""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest

from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners
from vbl_robust.geometry.geodesy import (
    EARTH_RADIUS_M,
    SPHERE,
    RunwayFrame,
    ecef_to_geodetic,
    geodetic_to_ecef,
    runway_db_entry,
)

# (lat, lon, alt, azimuth): mid-latitude, southern hemisphere near the antimeridian, high latitude
SITES = [(43.6291, 1.3638, 151.0, 143.2), (-41.3272, 174.8053, 12.0, 336.7), (64.13, -21.94, 52.0, 10.0),
         (0.5, -179.99, 3.0, 270.0)]


def test_sphere_constants():
    assert SPHERE.semimajor_axis == SPHERE.semiminor_axis == EARTH_RADIUS_M == 6_371_010.0


@pytest.mark.parametrize("site", SITES)
def test_ecef_matches_pymap3d_and_round_trips(site):
    lat, lon, alt, _ = site
    xyz = geodetic_to_ecef(lat, lon, alt)
    ref = pymap3d.geodetic2ecef(lat, lon, alt, ell=SPHERE)
    np.testing.assert_allclose(xyz, ref, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(xyz), EARTH_RADIUS_M + alt, atol=1e-6)
    la, lo, al = ecef_to_geodetic(xyz)
    assert abs(la - lat) < 1e-11 and abs(lo - lon) < 1e-11 and abs(al - alt) < 1e-6


@pytest.mark.parametrize("site", SITES)
def test_runway_frame_axes_match_pymap3d_enu(site):
    lat, lon, alt, az = site
    frame = RunwayFrame.from_ltp(lat, lon, alt, az)
    # a point 1 km along the runway azimuth at the same ENU height → x = 1000, y = 0
    e, n, u = 1000 * math.sin(math.radians(az)), 1000 * math.cos(math.radians(az)), 5.0
    p = pymap3d.enu2geodetic(e, n, u, lat, lon, alt, ell=SPHERE)
    np.testing.assert_allclose(frame.to_runway(*p), [1000.0, 0.0, 5.0], atol=1e-6)
    # a point 100 m to the left (bearing az − 90) → y = +100
    e, n = 100 * math.sin(math.radians(az - 90)), 100 * math.cos(math.radians(az - 90))
    p = pymap3d.enu2geodetic(e, n, 0.0, lat, lon, alt, ell=SPHERE)
    np.testing.assert_allclose(frame.to_runway(*p), [0.0, 100.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("site", SITES)
def test_runway_geodetic_round_trip_sub_mm(site):
    frame = RunwayFrame.from_ltp(*site)
    rng = np.random.default_rng(0)
    pts = rng.uniform([-8000, -2000, -50], [4000, 2000, 1500], size=(200, 3))
    back = frame.to_runway(*frame.to_geodetic(pts))
    assert np.max(np.abs(back - pts)) < 1e-3


@pytest.mark.parametrize("site", SITES)
@pytest.mark.parametrize("dims", [(1500.0, 30.0, 0.0), (3500.0, 45.0, -7.5), (4000.0, 60.0, 12.0)])
def test_db_entry_reads_back_exactly(site, dims):
    lat, lon, alt, az = site
    entry = runway_db_entry(lat, lon, alt, az, *dims)
    assert list(entry) == ["A", "B", "C", "D"]
    for c in entry.values():
        pos = c["position"]
        co = c["coordinate"]
        np.testing.assert_allclose(
            [pos["x"], pos["y"], pos["z"]],
            geodetic_to_ecef(co["latitude"], co["longitude"], co["altitude"]), atol=1e-6)
    frame = RunwayFrame.from_corners(entry)
    assert abs(frame.ltp[0] - lat) < 1e-10 and abs(frame.ltp[1] - lon) < 1e-10
    assert abs(frame.ltp[2] - alt) < 1e-4
    assert abs(((frame.azimuth_deg - az + 180) % 360) - 180) < 1e-8
    np.testing.assert_allclose(frame.corners_3d, runway_corners(*dims), atol=1e-3)


def test_flat_db_runway_follows_the_sphere():
    entry = runway_db_entry(43.0, 1.0, 100.0, 90.0, 4000.0, 45.0, 0.0)
    # the tangent plane rises above the sphere: far end altitude ≈ L²/2R higher than the threshold
    assert entry["A"]["coordinate"]["altitude"] - 100.0 == pytest.approx(4000.0**2 / (2 * EARTH_RADIUS_M), rel=1e-3)


def test_azimuth_from_corners_quadrants():
    for az in (0.0, 45.0, 90.0, 179.9, 180.0, 270.0, 359.5):
        frame = RunwayFrame.from_corners(runway_db_entry(10.0, 20.0, 0.0, az, 2000.0, 40.0))
        assert abs(((frame.azimuth_deg - az + 180) % 360) - 180) < 1e-8
        assert 0.0 <= frame.azimuth_deg < 360.0


def test_corners_as_array_and_errors():
    entry = runway_db_entry(43.0, 1.0, 100.0, 30.0, 3000.0, 45.0)
    arr = [[c["coordinate"]["latitude"], c["coordinate"]["longitude"], c["coordinate"]["altitude"]]
           for c in entry.values()]
    np.testing.assert_allclose(RunwayFrame.from_corners(arr).corners_3d, runway_corners(3000.0, 45.0), atol=1e-3)
    with pytest.raises(ValueError, match="shape"):
        RunwayFrame.from_corners(arr[:3])
    bad = dict(entry)
    bad["C"] = {"coordinate": {"latitude": 1.0}}
    with pytest.raises(ValueError, match="corner 'C'"):
        RunwayFrame.from_corners(bad)
    with pytest.raises(ValueError, match="latitude"):
        RunwayFrame.from_ltp(95.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        runway_db_entry(43.0, 1.0, float("nan"), 30.0, 3000.0, 45.0)
    with pytest.raises(ValueError, match="positive"):
        runway_db_entry(43.0, 1.0, 0.0, 30.0, -3000.0, 45.0)
    with pytest.raises(ValueError, match="built from an LTP"):
        _ = RunwayFrame.from_ltp(43.0, 1.0, 0.0, 0.0).corners_3d


@pytest.mark.parametrize("site", SITES)
def test_camera_through_lat_lon_alt_reprojects_identically(site):
    lat, lon, alt, az = site
    dims = (3000.0, 45.0, 2.0)
    frame = RunwayFrame.from_corners(runway_db_entry(lat, lon, alt, az, *dims))
    K = intrinsics()
    corners = frame.corners_3d
    rng = np.random.default_rng(1)
    for _ in range(20):
        C = np.array([-rng.uniform(300, 6000), rng.uniform(-300, 300), rng.uniform(20, 400)])
        yaw = az + rng.uniform(-10, 10)
        pitch_lard = 90 + rng.uniform(-8, 3)
        roll = rng.uniform(-20, 20)
        R = lard_rotation(yaw, pitch_lard, roll, az)
        uv = project(corners, R, C, K)
        # to a LARD row (lat/lon/alt + yaw/pitch/roll) and back
        cam = frame.to_geodetic(C)
        yaw2, pitch2, roll2 = frame.camera_attitude(R)
        C2 = frame.to_runway(*cam)
        R2 = frame.camera_rotation(yaw2, pitch2, roll2)
        assert np.linalg.norm(C2 - C) < 1e-3
        np.testing.assert_allclose(R2, R, atol=1e-12)
        np.testing.assert_allclose(project(corners, R2, C2, K), uv, atol=1e-6)


def test_heading_is_the_wgs84_geodesic_azimuth():
    # along a meridian or the equator sphere and ellipsoid agree; on a diagonal at mid-latitude they differ by
    # about e²·cos²φ·sin(2·az)/2 (the reason the yaw reference is the WGS84 heading, see module docstring)
    for lat, az in ((0.0, 90.0), (45.0, 0.0), (45.0, 180.0)):
        f = RunwayFrame.from_corners(runway_db_entry(lat, 10.0, 0.0, az, 3000.0, 45.0))
        assert abs(((f.heading_deg - az + 180) % 360) - 180) < 1e-4
    f = RunwayFrame.from_corners(runway_db_entry(53.33, -113.57, 712.0, 214.86, 3300.0, 62.0))
    e2 = 6.69438e-3
    expected = math.degrees(e2 * math.cos(math.radians(53.33)) ** 2 * math.sin(2 * math.radians(214.86)) / 2)
    assert f.heading_deg - f.azimuth_deg == pytest.approx(expected, rel=0.05)
    R = f.camera_rotation(f.heading_deg, 90.0, 0.0)
    np.testing.assert_allclose(R, np.eye(3), atol=1e-12)  # yaw = heading: camera looks down the runway axis
