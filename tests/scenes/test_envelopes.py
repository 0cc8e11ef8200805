import math

import numpy as np
import pytest

from vbl_robust.geometry.camera import intrinsics, lard_attitude, lard_rotation, to_camera
from vbl_robust.scenes.envelopes import (
    ENVELOPES,
    GLIDE_PATH_ANCHOR_M,
    approach_from_angles,
    corners_visible,
    sample_approaches,
)


def _inside(x, lo_hi, tol=1e-9):
    return lo_hi[0] - tol <= x <= lo_hi[1] + tol


@pytest.mark.parametrize("name", ["far", "medium", "close"])
def test_envelope_ranges_respected(name):
    env = ENVELOPES[name]
    apps = sample_approaches(300, seed=3, envelopes=[name], require_visible=False)
    for a in apps:
        assert a.envelope == name
        assert _inside(a.distance_m, env.distance_m)
        assert _inside(a.lateral_angle_deg, env.lateral_angle_deg)
        assert _inside(a.vertical_angle_deg, env.vertical_angle_deg)
        assert _inside(a.yaw_offset_deg, env.yaw_offset_deg)
        assert _inside(a.aero_pitch_deg, env.pitch_deg)
        assert _inside(a.roll_deg, env.roll_deg)
        assert 1500 <= a.runway_length_m <= 4000 and 30 <= a.runway_width_m <= 60
        # geometry recomputed from the camera position
        C = a.position
        assert math.hypot(C[0], C[1]) == pytest.approx(a.distance_m, rel=1e-12)
        assert math.degrees(math.atan2(C[1], -C[0])) == pytest.approx(a.lateral_angle_deg, abs=1e-9)
        assert C[2] == pytest.approx(-math.tan(math.radians(a.vertical_angle_deg)) * (a.distance_m + 305.0))
        # the rotation is the LARD one, and its attitude round-trips
        np.testing.assert_allclose(a.R, lard_rotation(a.yaw_deg, a.pitch_deg, a.roll_deg, a.runway_azimuth_deg))
        yaw, pitch, roll = lard_attitude(a.R, a.runway_azimuth_deg)
        assert (yaw - a.yaw_deg + 180) % 360 - 180 == pytest.approx(0, abs=1e-9)
        assert pitch == pytest.approx(a.pitch_deg) and roll == pytest.approx(a.roll_deg)
    # uniform sampling really spans the range
    d = np.array([a.distance_m for a in apps])
    lo, hi = env.distance_m
    assert d.min() < lo + 0.1 * (hi - lo) and d.max() > hi - 0.1 * (hi - lo)


def test_position_golden_values():
    a = approach_from_angles("close", 1000.0, 0.0, -3.0, 0.0, -3.0, 0.0, 3000.0, 45.0, 90.0)
    np.testing.assert_allclose(a.position, [-1000.0, 0.0, math.tan(math.radians(3.0)) * (1000.0 + GLIDE_PATH_ANCHOR_M)])
    # left of the centreline for a positive lateral angle
    b = approach_from_angles("close", 1000.0, 2.0, -3.0, 0.0, -3.0, 0.0, 3000.0, 45.0, 90.0)
    assert b.position[1] > 0
    # zero offsets: camera looks along the runway, pitched 3 deg down; LARD stores pitch 87
    assert a.pitch_deg == pytest.approx(87.0) and a.yaw_deg == pytest.approx(90.0)
    fwd = a.R[:, 0]
    np.testing.assert_allclose(fwd, [math.cos(math.radians(3)), 0.0, -math.sin(math.radians(3))], atol=1e-12)


def test_prefix_and_determinism():
    a = sample_approaches(5, seed=11)
    b = sample_approaches(20, seed=11)
    for x, y in zip(a, b[:5], strict=True):
        np.testing.assert_array_equal(x.position, y.position)
        np.testing.assert_array_equal(x.R, y.R)
        assert x.envelope == y.envelope and x.runway_azimuth_deg == y.runway_azimuth_deg
    c = sample_approaches(5, seed=12)
    assert not np.allclose(a[0].position, c[0].position)


def test_weights_and_envelope_choice():
    apps = sample_approaches(200, seed=0, weights=[1, 0, 3])
    names = [a.envelope for a in apps]
    assert "medium" not in names and names.count("close") > names.count("far")


def test_require_visible_with_narrow_camera():
    # a 20 deg camera often misses the runway; require_visible must still deliver visible poses
    W = H = 256
    K = intrinsics(W, H, 20.0)
    free = sample_approaches(200, seed=5, envelopes=["close"], require_visible=False, width=W, height=H, fov_deg=20)
    assert np.mean([corners_visible(a, K, W, H, 4.0) for a in free]) < 0.9
    vis = sample_approaches(50, seed=5, envelopes=["close"], width=W, height=H, fov_deg=20, margin_px=4.0)
    assert all(corners_visible(a, K, W, H, 4.0) for a in vis)
    assert max(a.tries for a in vis) > 1
    for a in vis:  # all corners in front of the camera
        assert np.all(to_camera(a.corners_3d, a.R, a.position)[:, 0] > 0)


def test_default_camera_always_sees_runway():
    K = intrinsics()
    apps = sample_approaches(300, seed=9, require_visible=False)
    assert all(corners_visible(a, K, 1024, 1024, 8.0) for a in apps)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"envelopes": ["nearby"]}, "unknown envelope"),
        ({"envelopes": []}, "at least one"),
        ({"weights": [1, 2]}, "weights"),
        ({"weights": [1, -1, 1]}, "weights"),
        ({"runway_length_range_m": (3000.0, 2000.0)}, "runway_length_range_m"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sample_approaches(3, seed=0, **kwargs)


def test_bad_n():
    with pytest.raises(ValueError, match="n:"):
        sample_approaches(-1)
