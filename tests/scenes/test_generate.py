import numpy as np
import pytest

import vbl_robust as vr
from vbl_robust.geometry.camera import intrinsics, project, runway_corners, to_camera
from vbl_robust.scenes.airports import REFERENCE_LAT_LON_ALT, designation, make_airports
from vbl_robust.scenes.generate import generate
from vbl_robust.scenes.render import ground_homography

META_KEYS = {"envelope", "airport", "runway", "runway_azimuth_deg", "runway_length_m", "runway_width_m",
             "yaw", "pitch", "roll"}


def test_public_entry_point_and_labels_exact():
    samples = vr.scenes.generate(6, seed=4, width=200, height=160, fov_deg=50.0)
    assert len(samples) == 6
    for s in samples:
        assert isinstance(s, vr.Sample)
        assert s.width == 200 and s.height == 160
        np.testing.assert_array_equal(s.K, intrinsics(200, 160, 50.0))
        np.testing.assert_array_equal(s.corners_3d, runway_corners(s.meta["runway_length_m"], s.meta["runway_width_m"]))
        np.testing.assert_allclose(s.corners_2d, project(s.corners_3d, s.R, s.position, s.K), rtol=0, atol=1e-9)
        assert np.all(to_camera(s.corners_3d, s.R, s.position)[:, 0] > 0)
        assert s.corners_in_image(margin_px=8.0)
        assert META_KEYS <= set(s.meta)
        assert 85.0 - 15.0 <= s.meta["pitch"] <= 95.0
        assert s.meta["airport"].startswith("XS")
    assert len({s.id for s in samples}) == 6


def test_ground_homography_matches_projection():
    s = generate(1, seed=2, width=64, height=64)[0]
    Hg = ground_homography(s.R, s.position, s.K)
    p = np.column_stack([s.corners_3d[:, :2], np.ones(4)]) @ Hg.T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:], s.corners_2d, atol=1e-9)


def test_same_seed_same_pixels_and_prefix():
    a = generate(3, seed=7, width=128, height=128)
    b = generate(5, seed=7, width=128, height=128)
    for x, y in zip(a, b[:3], strict=True):
        assert x.id == y.id
        np.testing.assert_array_equal(x.corners_2d, y.corners_2d)
        assert x.image.dtype == np.uint8 and x.image.shape == (128, 128, 3)
        np.testing.assert_array_equal(x.image, y.image)
    c = generate(1, seed=8, width=128, height=128)[0]
    assert not np.array_equal(c.image, a[0].image)
    # pixels re-render identically after being dropped
    img = a[0].image.copy()
    a[0].drop_pixels()
    np.testing.assert_array_equal(a[0].image, img)


def test_images_are_varied_and_not_flat():
    imgs = [s.image for s in generate(3, seed=1, width=96, height=96)]
    for img in imgs:
        assert img.std() > 5.0
    assert not np.array_equal(imgs[0], imgs[1])


def test_airports_and_designation():
    assert designation(87.0) == "09" and designation(3.0) == "36" and designation(271.0, "L") == "27L"
    pool = make_airports(5, seed=3)
    assert [a.icao for a in pool] == ["XS01", "XS02", "XS03", "XS04", "XS05"]
    assert make_airports(2, seed=3) == pool[:2]
    for a in pool:
        assert 1500 <= a.length_m <= 4000 and 30 <= a.width_m <= 60
        assert abs(a.ltp_lat - REFERENCE_LAT_LON_ALT[0]) < 1.0 and abs(a.ltp_lon - REFERENCE_LAT_LON_ALT[1]) < 4.0
        assert a.runway[:2] == designation(a.azimuth_deg)[:2]


@pytest.mark.parametrize("kwargs, match", [
    ({"n": -1}, "n:"), ({"n": 2, "width": 8}, "width"), ({"n": 2, "envelopes": ["low"]}, "envelope"),
    ({"n": 2, "n_airports": 0}, "n_airports"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        generate(**kwargs)
