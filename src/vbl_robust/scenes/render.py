"""Render approach images through ground-plane homographies, with the runway exactly where its corners project.

How a frame is made
-------------------
1. **Per-pixel geometry on a coarse grid** (every :data:`STRIDE` px): the ray of each cell centre, where it hits
   the ground plane ``z = 0`` (only rays pointing down: nothing behind the camera or above the horizon is ever
   mapped to the ground, so the plane cannot "wrap"), its range, and the ground footprint of one pixel along the
   runway axes (the Jacobian of the inverse homography).
2. **Footprint bands**: cells are grouped by ``log2`` of their footprint (like mip levels). For each band a ground
   tile is built whose texel size equals the smallest footprint of the band (per axis), so the tile is never
   minified by more than about 2×: the world raster is resampled from its pyramid, fine detail noise is
   multiplied in, and the airport layout is painted with exact area coverage (:func:`.layout.paint`).
3. Each tile is warped into the image with ``cv2.warpPerspective`` through ``H · A`` where ``H = K [r1 r2 t]``
   is the ground → image homography of the labelled pose and ``A`` maps texels to ground metres. OpenCV's
   convention (pixel centres at integer coordinates, in the tile and in the image) is used on both sides, so the
   painted runway edge crosses 50 % exactly where :func:`vbl_robust.geometry.camera.project` puts it (up to the
   ≤ 0.1 texel bias of bilinear reconstruction of a box-filtered edge and OpenCV's 1/32 px warp precision).
4. **Sky and aerial perspective**: a sky gradient with sun glow; the ground is blended toward the horizon haze
   colour with transmittance ``exp(−range / visibility)``; both are computed on the coarse grid and upsampled
   (they are smooth; at the horizon the ground is fully hazed, so sky and ground meet without a seam).
5. Sensor: optional Gaussian blur, then noise from a cached buffer, then a per-channel tone curve (LUT).

``Look`` holds all appearance choices of a frame (drawn by :func:`sample_look` from a seed). ``debug=True``
renders a black world with the runway surface flat white and no haze, blur, noise or markings: the pixel checks
of the tests use it.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import cv2
import numpy as np

from vbl_robust.geometry.camera import world_to_cv

from .layout import paint
from .textures import (
    DETAIL_TEXEL_M,
    N_WORLDS,
    WORLD_SIZE,
    WORLD_TEXEL_M,
    detail_pyramid,
    sensor_noise,
    world_pyramid,
)

#: Coarse grid step (pixels) of the per-pixel geometry.
STRIDE = 8
#: Smallest texel size (metres) of a ground tile.
MIN_TEXEL_M = 0.02
#: Largest ground tile (texels); beyond it the texel size grows (only far, hazy bands ever reach it).
MAX_TILE_TEXELS = 1_500_000
#: Ground farther than this (metres) is drawn in the world's mean colour (it is hazed and sub-pixel anyway).
MAX_RANGE_M = 30_000.0
#: Largest tile side (OpenCV warps need < 32767).
MAX_TILE_SIDE = 8192


@dataclass(frozen=True)
class Look:
    """Appearance of one frame (colours are RGB in [0, 1])."""

    sky_zenith: tuple[float, float, float]
    sky_horizon: tuple[float, float, float]
    sun_dir: tuple[float, float, float]  # unit vector toward the sun, runway frame
    sun_rgb: tuple[float, float, float]
    visibility_m: float
    ground_gain: tuple[float, float, float]
    detail_amp: float
    blur_sigma: float
    noise_scale: float  # multiple of the sensor-noise buffer std (16 grey levels)
    gamma: float
    world: int
    world_offset: tuple[float, float]
    debug: bool = False


def sample_look(rng: np.random.Generator, world: int = 0, world_offset: tuple[float, float] = (0.0, 0.0),
                runway_azimuth_deg: float = 0.0) -> Look:
    """Draw the appearance of one frame (sun, sky, haze, lighting, sensor) from ``rng``."""
    overcast = rng.random() < 0.25
    sun_el = math.radians(rng.uniform(8.0, 70.0))
    sun_az = math.radians(rng.uniform(0.0, 360.0) - runway_azimuth_deg)  # relative to the runway axis
    # runway frame: x along the runway, y left; an azimuth a (clockwise from the runway) is (cos a, −sin a)
    sun_dir = (math.cos(sun_el) * math.cos(sun_az), -math.cos(sun_el) * math.sin(sun_az), math.sin(sun_el))
    warm = max(0.0, 1.0 - math.degrees(sun_el) / 25.0)  # low sun: warmer light
    if overcast:
        g = rng.uniform(0.55, 0.8)
        zen = (g * 0.95, g * 0.97, g)
        hor = tuple(min(1.0, c * 1.08) for c in zen)
        light = rng.uniform(0.75, 1.0)
        gain = (light, light, light * 1.02)
        sun_rgb = (0.0, 0.0, 0.0)
        vis = float(np.exp(rng.uniform(np.log(6000.0), np.log(25000.0))))
    else:
        b = rng.uniform(0.75, 1.05)
        zen = (0.20 * b + 0.1 * warm, 0.40 * b + 0.05 * warm, 0.78 * b)
        hor = (0.72 + 0.15 * warm, 0.78 + 0.06 * warm, 0.86 - 0.05 * warm)
        hor = tuple(float(np.clip(c * rng.uniform(0.9, 1.05), 0, 1)) for c in hor)
        light = 0.6 + 0.65 * math.sin(sun_el)
        gain = (light * (1.0 + 0.12 * warm), light, light * (1.0 - 0.15 * warm))
        sun_rgb = (1.0, 0.9 - 0.1 * warm, 0.75 - 0.2 * warm)
        vis = float(np.exp(rng.uniform(np.log(8000.0), np.log(60000.0))))
    tint = rng.normal(1.0, 0.04, 3)
    return Look(
        sky_zenith=tuple(float(c) for c in zen),
        sky_horizon=tuple(float(c) for c in hor),
        sun_dir=tuple(float(c) for c in sun_dir),
        sun_rgb=tuple(float(c) for c in sun_rgb),
        visibility_m=vis,
        ground_gain=tuple(float(g * t) for g, t in zip(gain, tint, strict=True)),
        detail_amp=float(rng.uniform(0.06, 0.16)),
        blur_sigma=float(rng.choice([0.0, rng.uniform(0.4, 1.1)])),
        noise_scale=float(rng.uniform(0.05, 0.3)),
        gamma=float(rng.uniform(0.85, 1.15)),
        world=int(world) % N_WORLDS,
        world_offset=(float(world_offset[0]), float(world_offset[1])),
    )


def debug_look() -> Look:
    """A look for pixel checks: black world and sky, no haze, blur, noise or tone curve."""
    return Look((0, 0, 0), (0, 0, 0), (0, 0, 1), (0, 0, 0), math.inf, (1, 1, 1), 0.0, 0.0, 0.0, 1.0, 0, (0, 0),
                debug=True)


def ground_homography(R: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(3, 3) homography from ground-plane points ``(x, y, 1)`` (runway frame, z = 0) to pixels."""
    R_cv, t = world_to_cv(R, C)
    return np.asarray(K, dtype=np.float64) @ np.column_stack([R_cv[:, 0], R_cv[:, 1], t])


@dataclass
class _Grid:
    """Per-cell geometry on the coarse grid (arrays of shape (gh, gw))."""

    d: np.ndarray  # (gh, gw, 3) ray directions in the runway frame (forward component 1 in the camera)
    ground: np.ndarray  # bool, ray hits the ground
    gx: np.ndarray
    gy: np.ndarray
    rng_m: np.ndarray  # range to the ground hit (inf where none)
    fx: np.ndarray  # ground footprint of a pixel along runway x / y, metres
    fy: np.ndarray
    iso: np.ndarray  # sqrt of the ground area of a pixel, metres
    box: np.ndarray  # (4, gh, gw) ground bounding box (xmin, xmax, ymin, ymax) of each cell (±inf at the horizon)


def _hits(R, C, K, u: np.ndarray, v: np.ndarray):
    """Rays through pixels ``(u[j], v[i])``: directions, ground mask, hit x/y, range, footprints fx, fy, iso."""
    R = np.asarray(R, dtype=np.float64)
    du = -R[:, 1] / K[0, 0]
    dv = -R[:, 2] / K[1, 1]
    d0 = R[:, 0] - du * K[0, 2] - dv * K[1, 2]
    d = d0[None, None, :] + u[None, :, None] * du[None, None, :] + v[:, None, None] * dv[None, None, :]
    dz = d[..., 2]
    ground = dz < -1e-9
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.where(ground, -C[2] / dz, np.inf)
        gx = C[0] + t * d[..., 0]
        gy = C[1] + t * d[..., 1]
        rng_m = t * np.linalg.norm(d, axis=-1)
        k = -C[2] / dz**2
        a = k * (du[0] * dz - d[..., 0] * du[2])  # d gx / du
        b = k * (dv[0] * dz - d[..., 0] * dv[2])  # d gx / dv
        c = k * (du[1] * dz - d[..., 1] * du[2])  # d gy / du
        e = k * (dv[1] * dz - d[..., 1] * dv[2])  # d gy / dv
        iso = np.sqrt(np.abs(a * e - b * c))
    fx = np.where(ground, np.maximum(np.abs(a), np.abs(b)), np.inf)
    fy = np.where(ground, np.maximum(np.abs(c), np.abs(e)), np.inf)
    return d, ground, gx, gy, rng_m, fx, fy, iso


def _grid(R, C, K, width, height, stride) -> _Grid:
    gw, gh = -(-width // stride), -(-height // stride)
    u = stride * np.arange(gw) + (stride - 1) / 2.0
    v = stride * np.arange(gh) + (stride - 1) / 2.0
    d, ground, gx, gy, rng_m, fx, fy, iso = _hits(R, C, K, u, v)
    # cell corners: their ground hits bound each cell's ground region (infinite where a corner is above the
    # horizon) and their footprints bound the footprints inside the cell from below (near the horizon the
    # footprint changes by large factors within one cell)
    uc = stride * np.arange(gw + 1) - 0.5
    vc = stride * np.arange(gh + 1) - 0.5
    _, gc, cx, cy, _, cfx, cfy, _ = _hits(R, C, K, uc, vc)

    def four(a):
        return np.stack([a[:-1, :-1], a[1:, :-1], a[:-1, 1:], a[1:, 1:]])

    open_cell = ~four(gc).all(axis=0)
    cxs, cys = four(np.where(gc, cx, np.nan)), four(np.where(gc, cy, np.nan))
    with warnings.catch_warnings():  # all-NaN cells are open cells, replaced by ±inf
        warnings.simplefilter("ignore", RuntimeWarning)
        box = np.stack([
            np.where(open_cell, -np.inf, np.nanmin(cxs, axis=0)),
            np.where(open_cell, np.inf, np.nanmax(cxs, axis=0)),
            np.where(open_cell, -np.inf, np.nanmin(cys, axis=0)),
            np.where(open_cell, np.inf, np.nanmax(cys, axis=0)),
        ])
    fx = np.minimum(fx, four(cfx).min(axis=0))
    fy = np.minimum(fy, four(cfy).min(axis=0))
    return _Grid(d, ground, gx, gy, rng_m, fx, fy, iso, box)


def _world_matrix(look: Look, level: int) -> np.ndarray:
    """(3, 3) map from texel coordinates of world pyramid ``level`` to ground metres (runway frame)."""
    s = WORLD_TEXEL_M * 2**level
    c = (WORLD_SIZE - 1) / 2.0 * WORLD_TEXEL_M
    ox, oy = look.world_offset
    return np.array([[s, 0.0, -c - ox], [0.0, s, -c - oy], [0.0, 0.0, 1.0]])


def _detail_matrix(look: Look, level: int) -> np.ndarray:
    s = DETAIL_TEXEL_M * 2**level
    ox, oy = look.world_offset
    return np.array([[s, 0.0, -ox], [0.0, s, -oy], [0.0, 0.0, 1.0]])


def _layout_bounds(layout: np.ndarray) -> tuple[float, float, float, float]:
    return (float(layout[:, 0].min()), float(layout[:, 1].max()), float(layout[:, 4].min()),
            float(layout[:, 5].max()))


def _airport_tile(look: Look, layout: np.ndarray, g: _Grid, sel: np.ndarray, bounds) -> tuple | None:
    """Premultiplied RGBA tile (ny, nx, 4) of the layout for one band, with its texel → ground matrix."""
    bx0, bx1, by0, by1 = bounds
    x_lo, x_hi, y_lo, y_hi = g.box
    inside = sel & (x_hi > bx0) & (x_lo < bx1) & (y_hi > by0) & (y_lo < by1)
    if not inside.any():
        return None
    sx = max(float(g.fx[inside].min()), MIN_TEXEL_M)
    sy = max(float(g.fy[inside].min()), MIN_TEXEL_M)
    xmin, xmax = max(float(x_lo[inside].min()), bx0) - 2 * sx, min(float(x_hi[inside].max()), bx1) + 2 * sx
    ymin, ymax = max(float(y_lo[inside].min()), by0) - 2 * sy, min(float(y_hi[inside].max()), by1) + 2 * sy
    if xmax <= xmin or ymax <= ymin:
        return None
    nx, ny = (xmax - xmin) / sx + 1, (ymax - ymin) / sy + 1
    scale = max(1.0, math.sqrt(nx * ny / MAX_TILE_TEXELS), nx / MAX_TILE_SIDE, ny / MAX_TILE_SIDE)
    sx, sy = sx * scale, sy * scale
    nx, ny = int((xmax - xmin) / sx) + 2, int((ymax - ymin) / sy) + 2
    tile = np.zeros((ny, nx, 4), np.float32)
    paint(tile, xmin, ymin, sx, sy, layout)
    if not look.debug and look.detail_amp > 0:
        det = _detail_on_grid(look, xmin, ymin, sx, sy, nx, ny)
        if det is not None:
            tile[..., :3] *= det[..., None]
    A = np.array([[sx, 0.0, xmin], [0.0, sy, ymin], [0.0, 0.0, 1.0]])
    return tile, A


def _detail_on_grid(look: Look, x0: float, y0: float, sx: float, sy: float, nx: int, ny: int):
    """Multiplicative fine texture ``1 + a·noise`` sampled on a tile grid, or None when the texels are coarse."""
    s = min(sx, sy)
    if s >= WORLD_TEXEL_M:
        return None
    pyr = detail_pyramid()
    lvl = int(np.clip(math.floor(math.log2(max(s, DETAIL_TEXEL_M) / DETAIL_TEXEL_M)), 0, len(pyr) - 1))
    noise = pyr[lvl]
    n = noise.shape[0]
    sl = DETAIL_TEXEL_M * 2**lvl
    ix = np.floor((x0 + look.world_offset[0] + sx * np.arange(nx)) / sl).astype(np.int64) % n
    iy = np.floor((y0 + look.world_offset[1] + sy * np.arange(ny)) / sl).astype(np.int64) % n
    return 1.0 + np.float32(1.5 * look.detail_amp) * noise[iy[:, None], ix[None, :]]


def _chunks(sel: np.ndarray, width_cells: int):
    """Boxes (r0, r1, c0, c1) in cells covering ``sel``, one per column chunk (tight for tilted stripes)."""
    gh, gw = sel.shape
    for c0 in range(0, gw, width_cells):
        c1 = min(c0 + width_cells, gw)
        rows = np.flatnonzero(sel[:, c0:c1].any(axis=1))
        if rows.size:
            cols = np.flatnonzero(sel[rows[0]:rows[-1] + 1, c0:c1].any(axis=0))
            yield rows[0], rows[-1] + 1, c0 + cols[0], c0 + cols[-1] + 1


def _render_ground(R, C, K, width, height, layout, look, g: _Grid, r_max: float) -> np.ndarray:
    """Ground layer (height, width, 3) float32 (lit albedo); ground beyond ``r_max`` gets the world mean."""
    H = ground_homography(R, C, K)
    S = STRIDE
    gain = np.asarray(look.ground_gain, np.float32)
    out = np.empty((height, width, 3), np.float32)
    if look.debug:
        out[:] = 0.0
    else:
        pyr = world_pyramid(look.world)
        out[:] = pyr[-1].reshape(-1, 3).mean(axis=0) / 255.0 * gain
    valid = g.ground & (g.rng_m < r_max)
    if not valid.any():
        return out
    level = np.where(valid, np.floor(np.log2(np.maximum(g.iso, MIN_TEXEL_M) / MIN_TEXEL_M)), -1).astype(np.int32)
    bounds = _layout_bounds(layout)
    dpyr = detail_pyramid()
    for k in np.unique(level[level >= 0]):
        sel = level == k
        iso_min = float(g.iso[sel].min())
        tile = _airport_tile(look, layout, g, sel, bounds)
        if not look.debug:
            m = int(np.clip(math.floor(math.log2(max(iso_min, WORLD_TEXEL_M) / WORLD_TEXEL_M)), 0, len(pyr) - 1))
            Hw = H @ _world_matrix(look, m)
            dl = None
            if iso_min < 2 * WORLD_TEXEL_M and look.detail_amp > 0:
                dl = int(np.clip(math.floor(math.log2(max(iso_min, DETAIL_TEXEL_M) / DETAIL_TEXEL_M)), 0,
                                 len(dpyr) - 1))
                Hd = H @ _detail_matrix(look, dl)
                amp = np.float32(look.detail_amp * min(1.0, 2 * WORLD_TEXEL_M / iso_min - 1.0))
        for r0, r1, c0, c1 in _chunks(sel, 16):
            v0, v1, u0, u1 = r0 * S, min(r1 * S, height), c0 * S, min(c1 * S, width)
            size = (u1 - u0, v1 - v0)
            T = np.array([[1.0, 0.0, -u0], [0.0, 1.0, -v0], [0.0, 0.0, 1.0]])
            if look.debug:
                col = np.zeros((v1 - v0, u1 - u0, 3), np.float32)
            else:
                col = cv2.warpPerspective(pyr[m], T @ Hw, size, flags=cv2.INTER_LINEAR,
                                          borderMode=cv2.BORDER_REFLECT_101).astype(np.float32)
                if dl is not None:
                    det = cv2.warpPerspective(dpyr[dl], T @ Hd, size, flags=cv2.INTER_LINEAR,
                                              borderMode=cv2.BORDER_WRAP)
                    det *= amp
                    det += 1.0
                    col *= det[..., None]
                col *= gain * np.float32(1.0 / 255.0)
            if tile is not None:
                rgba = cv2.warpPerspective(tile[0], T @ H @ tile[1], size, flags=cv2.INTER_LINEAR,
                                           borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                premult = rgba[..., :3] if look.debug else rgba[..., :3] * gain
                col = col * (1.0 - rgba[..., 3:4]) + premult
            mask = np.repeat(np.repeat(sel[r0:r1, c0:c1], S, axis=0), S, axis=1)[: v1 - v0, : u1 - u0]
            np.copyto(out[v0:v1, u0:u1], col, where=mask[..., None])
    return out


def _sky_and_weight(look: Look, g: _Grid) -> tuple[np.ndarray, np.ndarray]:
    """Coarse sky/haze colour (gh, gw, 3) and ground weight ``transmittance`` (gh, gw), float32."""
    dn = g.d / np.linalg.norm(g.d, axis=-1, keepdims=True)
    el = np.clip(dn[..., 2], 0.0, 1.0)
    zen, hor = np.asarray(look.sky_zenith, np.float32), np.asarray(look.sky_horizon, np.float32)
    mix = (1.0 - np.exp(-el / 0.12))[..., None]
    sky = hor + (zen - hor) * mix
    cosg = dn @ np.asarray(look.sun_dir)
    glow = 0.9 * np.exp((cosg - 1.0) / 0.0015) + 0.25 * np.exp((cosg - 1.0) / 0.06)
    sky = sky + glow[..., None] * np.asarray(look.sun_rgb, np.float32)
    w = np.where(g.ground, np.exp(-np.where(g.ground, g.rng_m, 0.0) / look.visibility_m), 0.0)
    return sky.astype(np.float32), w.astype(np.float32)


def _upsample(a: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear upsampling of a coarse-grid map whose samples sit at cell centres (STRIDE·k + (STRIDE−1)/2)."""
    gh, gw = a.shape[:2]
    up = cv2.resize(a, (gw * STRIDE, gh * STRIDE), interpolation=cv2.INTER_LINEAR)
    return up[:height, :width]


def render_scene(R: np.ndarray, C: np.ndarray, K: np.ndarray, width: int, height: int, layout: np.ndarray,
                 look: Look, rng: np.random.Generator | None = None) -> np.ndarray:
    """Render one frame.

    Args:
        R: (3, 3) camera → runway rotation; C: (3,) camera position (runway frame, metres, ``C_z > 0``).
        K: (3, 3) intrinsics; width, height: image size in pixels.
        layout: (N, 12) layout rows (:mod:`.layout`) in the runway frame.
        look: appearance (:func:`sample_look` or :func:`debug_look`).
        rng: generator for the sensor-noise crop (default: fixed).

    Returns:
        (height, width, 3) uint8 RGB.
    """
    C = np.asarray(C, dtype=np.float64)
    if not C[2] > 0:
        raise ValueError(f"render_scene: camera must be above the ground (C_z > 0), got C = {C.tolist()}")
    K = np.asarray(K, dtype=np.float64)
    g = _grid(R, C, K, width, height, STRIDE)
    r_max = min(6.0 * look.visibility_m, MAX_RANGE_M)
    ground = _render_ground(R, C, K, width, height, layout, look, g, r_max)
    if look.debug:
        return cv2.convertScaleAbs(ground, alpha=255.0)
    sky, w = _sky_and_weight(look, g)
    sky_f = _upsample(sky, width, height)
    w_f = _upsample(w, width, height)
    img = cv2.blendLinear(ground, sky_f, w_f, 1.0 - w_f)
    img8 = cv2.convertScaleAbs(img, alpha=255.0)  # rounds and saturates to uint8 (values are >= 0)
    if look.blur_sigma > 0.3:
        img8 = cv2.GaussianBlur(img8, (0, 0), look.blur_sigma)
    if look.noise_scale > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        buf = sensor_noise(height, width)
        oy, ox = (int(v) for v in rng.integers(0, 64, 2))
        a = look.noise_scale
        img8 = cv2.addWeighted(img8, 1.0, buf[oy:oy + height, ox:ox + width], a, -128.0 * a)
    lut = np.clip(255.0 * (np.arange(256) / 255.0) ** (1.0 / look.gamma) + 0.5, 0, 255).astype(np.uint8)
    return cv2.LUT(img8, lut)


__all__ = ["Look", "debug_look", "ground_homography", "render_scene", "sample_look"]
