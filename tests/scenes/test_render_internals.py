"""The renderer's shortcuts give the same pixels as the straightforward way (grid boxes, borders, paint runs)."""

import cv2
import numpy as np
import pytest

from vbl_robust.scenes.generate import generate
from vbl_robust.scenes.grid import hits, make_grid
from vbl_robust.scenes.layout import paint, rect
from vbl_robust.scenes.render import _placement, _warp, _warp_smooth
from vbl_robust.scenes.textures import DETAIL_Q, detail_pyramid, detail_tiles


@pytest.mark.parametrize("envelope", ["close", "far"])
def test_cell_boxes_contain_every_ground_hit_within_the_clip_radius(envelope):
    rng = np.random.default_rng(0)
    clip = 20_000.0
    for s in generate(3, seed=11, width=256, height=256, envelopes=[envelope]):
        g = make_grid(s.R, s.position, s.K, 256, 256, 8, clip)
        u, v = rng.uniform(-0.5, 255.5, 4000), rng.uniform(-0.5, 255.5, 4000)  # anywhere inside the pixels
        for ui, vi in zip(u, v, strict=True):
            _, ground, gx, gy, *_ = hits(s.R, s.position, s.K, np.array([ui]), np.array([vi]))
            if not ground[0, 0] or np.hypot(gx[0, 0] - s.position[0], gy[0, 0] - s.position[1]) > clip:
                continue
            i, j = int((vi + 0.5) // 8), int((ui + 0.5) // 8)
            x0, x1, y0, y1 = g.box[:, i, j]
            assert x0 - 1e-6 <= gx[0, 0] <= x1 + 1e-6 and y0 - 1e-6 <= gy[0, 0] <= y1 + 1e-6


def test_padded_world_level_warps_like_a_reflected_border():
    from vbl_robust.scenes import textures

    level = 4
    padded = textures.world_pyramid(0)[level]
    p = textures.world_pad(level)
    assert p > 0
    plain = padded[p:-p, p:-p]
    # a view sampling far outside the raster: constant border on the padded level = reflection on the plain one
    M = np.array([[0.9, 0.2, -60.0], [-0.1, 1.1, -40.0], [0.0, 0.0, 1.0]])  # plain texels -> pixels
    shift = np.array([[1.0, 0.0, -p], [0.0, 1.0, -p], [0.0, 0.0, 1.0]])  # padded texels -> plain texels
    a = _warp(padded, M @ shift, (200, 150))
    b = _warp(np.ascontiguousarray(plain), M, (200, 150), cv2.BORDER_REFLECT_101)
    assert np.abs(a.astype(int) - b).max() <= 1  # (fixed-point rounding of the composed matrices)


def test_detail_placement_matches_a_wrapped_border():
    base = detail_pyramid()[1]
    tiled, period = detail_tiles()[1]
    q = np.clip(np.rint(128.0 + DETAIL_Q * base), 0, 255).astype(np.uint8)
    s = 0.2  # texel size of level 1, metres
    M = np.array([[s, 0.0, -3.0], [0.0, s, 7.0], [0.0, 0.0, 1.0]])  # texels -> ground metres
    H = np.array([[2.0, 0.3, 0.0], [-0.2, 2.5, 0.0], [0.0, 0.001, 1.0]])  # ground offset -> pixels
    box = (490.0, 530.0, -310.0, -270.0)  # far from the origin: many periods away
    Hg = H @ np.array([[1.0, 0.0, -500.0], [0.0, 1.0, 300.0], [0.0, 0.0, 1.0]])  # pixels 0..40 land in the box
    Mp, mode = _placement(tiled, M, box, period=period)
    assert mode == cv2.BORDER_CONSTANT
    a = _warp(tiled, Hg @ Mp, (40, 40), mode, 128)
    b = _warp(q, Hg @ M, (40, 40), cv2.BORDER_WRAP)
    assert np.abs(a.astype(int) - b).max() <= 1


def test_smooth_warp_of_a_magnified_texture_is_close_to_the_full_warp():
    rng = np.random.default_rng(1)
    src = cv2.resize(rng.integers(0, 256, (32, 32, 4), dtype=np.uint8), (256, 256), interpolation=cv2.INTER_LINEAR)
    M = np.array([[8.0, 1.0, -500.0], [-1.0, 8.0, -300.0], [0.0, 0.0, 1.0]])  # 8x magnification
    full = _warp(src, M, (300, 200)).astype(int)
    for q in (2, 4):
        smooth = _warp_smooth(src, M, (300, 200), cv2.BORDER_CONSTANT, 0, q).astype(int)
        assert smooth.shape == full.shape
        diff = np.abs(smooth - full)
        assert diff.max() <= 6 and diff.mean() < 0.3  # (no seams at the edges either)


def test_a_run_of_disjoint_same_paint_rows_adds_their_exact_coverages():
    white = (1.0, 1.0, 1.0)
    rows = np.asarray([rect(0.0, 1.3, 0.0, 2.0, white), rect(1.3, 2.05, 0.2, 1.1, white),
                       rect(3.0, 3.1, -1.0, 5.0, white)], dtype=np.float64)
    tile = np.zeros((12, 10, 4), np.float32)
    paint(tile, -0.7, -1.2, 0.6, 0.7, rows)  # one run: coverages add
    alone = np.zeros((len(rows), 12, 10, 4), np.float32)
    for k, r in enumerate(rows):
        paint(alone[k], -0.7, -1.2, 0.6, 0.7, r[None])
    np.testing.assert_allclose(tile[..., 3], alone[..., 3].sum(axis=0), atol=1e-6)
    assert tile[..., 3].sum() * 0.6 * 0.7 == pytest.approx(1.3 * 2.0 + 0.75 * 0.9 + 0.1 * 6.0, rel=1e-5)
