"""The rendered runway is where the labels say: flat-white debug renders checked pixel by pixel."""

import numpy as np
import pytest

from vbl_robust.scenes.generate import generate


def _edge_distances(quad: np.ndarray, width: int, height: int) -> np.ndarray:
    """Signed distance (px, positive inside) of every pixel centre to the convex quadrilateral ``quad`` (4, 2)."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    area2 = np.sum(quad[:, 0] * np.roll(quad[:, 1], -1) - np.roll(quad[:, 0], -1) * quad[:, 1])
    sign = 1.0 if area2 > 0 else -1.0
    dist = np.full(u.shape, np.inf)
    for k in range(4):
        p, q = quad[k], quad[(k + 1) % 4]
        e = q - p
        n = np.array([-e[1], e[0]]) * sign / np.hypot(*e)  # inward normal (image axes, v down)
        dist = np.minimum(dist, (u - p[0]) * n[0] + (v - p[1]) * n[1])
    return dist


def _polygon_area_centroid(quad):
    x, y = quad[:, 0], quad[:, 1]
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a = cross.sum() / 2
    cx = ((x + np.roll(x, -1)) * cross).sum() / (6 * a)
    cy = ((y + np.roll(y, -1)) * cross).sum() / (6 * a)
    return abs(a), np.array([cx, cy])


# (at 256 px the far half of a close runway is squeezed against the horizon: looser integral checks)
@pytest.mark.parametrize("envelope, size, rel_area, centroid_px", [
    ("close", 256, 0.05, 0.3), ("close", 1024, 0.005, 0.05), ("medium", 384, 0.02, 0.1), ("far", 512, 0.02, 0.1),
])
def test_runway_pixels_match_labels(envelope, size, rel_area, centroid_px):
    for s in generate(4, seed=21, width=size, height=size, envelopes=[envelope], debug=True):
        img = s.image.astype(np.float64) / 255.0
        assert np.ptp(img, axis=2).max() == 0.0  # flat grey levels only
        cov = img[..., 0]
        d = _edge_distances(s.corners_2d, size, size)
        # well inside: fully covered; well outside: nothing (within 1.5 px of an edge anything goes)
        assert np.all(cov[d > 1.5] > 0.97)
        assert np.all(cov[d < -1.5] < 0.03)
        # coverage integrates to the labelled quadrilateral: same area and centroid
        area, centroid = _polygon_area_centroid(s.corners_2d)
        assert cov.sum() == pytest.approx(area, rel=rel_area, abs=0.5)
        vv, uu = np.mgrid[0:size, 0:size]
        c = np.array([(cov * uu).sum(), (cov * vv).sum()]) / cov.sum()
        np.testing.assert_allclose(c, centroid, atol=centroid_px)


def test_far_runway_is_visible_in_normal_render():
    # at 4.5-6 km the runway is only a few pixels wide: it must still differ from its surroundings
    for s in generate(3, seed=5, envelopes=["far"]):
        img = s.image.astype(np.float64)
        d = _edge_distances(s.corners_2d, s.width, s.height)
        inside = img[d > 0.5].mean(axis=0)
        ring = img[(d < -3) & (d > -12)].mean(axis=0)
        assert np.abs(inside - ring).max() > 3.0
