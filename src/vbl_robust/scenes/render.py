"""Render approach images through ground-plane homographies, with the runway exactly where its corners project.

How a frame is made
-------------------
1. **Per-pixel geometry on a coarse grid** (every :data:`STRIDE` px, :mod:`.grid`): the ray of each cell centre,
   where it hits the ground plane ``z = 0`` (only rays pointing down: nothing behind the camera or above the
   horizon is ever mapped to the ground, so the plane cannot "wrap"), its range, the ground footprint of one pixel
   along the runway axes (the Jacobian of the inverse homography) and a ground box per cell.
2. **Footprint bands**: cells are grouped by ``log2`` of their footprint (like mip levels). Each band takes the
   world raster from the pyramid level that is never minified by more than about 2× (:mod:`.textures`), the
   detail noise likewise, and an airport tile painted with exact area coverage at the band's smallest footprint
   per axis (:mod:`.tiles`, :func:`.layout.paint`).
3. A band is drawn in blocks of :data:`CHUNK_ROWS` × :data:`CHUNK_CELLS` cells (small enough for the temporaries
   to stay in cache): each layer is warped into the block with ``cv2.warpPerspective`` through ``H · A`` where
   ``H = K [r1 r2 t]`` is the ground → image homography of the labelled pose and ``A`` maps texels to ground
   metres, then composited (albedo × light × transmittance + in-scattered haze) and copied where the block's
   cells belong to the band. OpenCV's convention (pixel centres at integer coordinates, in the tile and in the
   image) is used on both sides, so the painted runway edge crosses 50 % exactly where
   :func:`vbl_robust.geometry.camera.project` puts it (up to the ≤ 0.1 texel bias of bilinear reconstruction of a
   box-filtered edge and OpenCV's 1/32 px warp precision).
4. Speed: every warp keeps OpenCV's fast path (1 or 4 channels, constant border; textures that would need a
   reflected or periodic border are pre-extended instead), a world raster magnified 4× or more is warped at 1/2
   or 1/4 resolution and bilinearly upsampled (it is smooth at the pixel scale), and per-pixel products are
   OpenCV calls on 4-channel images rather than numpy broadcasts.
5. **Sky and aerial perspective**: a sky gradient with sun glow; the ground is blended toward the sky colour
   with transmittance ``exp(−range / visibility)``; both are computed on the coarse grid and upsampled (they are
   smooth; at the horizon the ground is fully hazed, so sky and ground meet without a seam).
6. Sensor: optional Gaussian blur, then noise from a cached buffer, then a per-channel tone curve (LUT).

``Look`` holds all appearance choices of a frame (drawn by :func:`sample_look` from a seed). ``debug=True``
renders a black world with the runway surface flat white and no haze, blur, noise or markings: the pixel checks
of the tests use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vbl_robust.geometry.camera import world_to_cv

from .grid import Grid, make_grid
from .textures import (
    DETAIL_Q,
    DETAIL_TEXEL_M,
    N_WORLDS,
    WORLD_SIZE,
    WORLD_TEXEL_M,
    detail_tiles,
    sensor_noise,
    world_mean,
    world_pad,
    world_pyramid,
)
from .tiles import MIN_TEXEL_M, airport_tiles

#: Coarse grid step (pixels) of the per-pixel geometry.
STRIDE = 8
#: Ground farther than this (metres) is drawn in the world's mean colour (it is hazed and sub-pixel anyway).
MAX_RANGE_M = 30_000.0
#: Ground boxes of the cells at the horizon are clipped at this multiple of the drawing range (horizontally).
CLIP_FACTOR = 1.0
#: Blocks (cells) in which a band is warped and composited: small enough for the temporaries to stay in cache.
CHUNK_CELLS = 16
CHUNK_ROWS = 16
#: Detail-noise amplitude on airport surfaces relative to the ground's (asphalt and concrete are rougher).
TILE_DETAIL_GAIN = 1.5


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


def _world_matrix(look: Look, level: int) -> np.ndarray:
    """(3, 3) map from texel coordinates of world pyramid ``level`` to ground metres (runway frame)."""
    s = WORLD_TEXEL_M * 2**level
    c = (WORLD_SIZE - 1) / 2.0 * WORLD_TEXEL_M + s * world_pad(level)
    ox, oy = look.world_offset
    return np.array([[s, 0.0, -c - ox], [0.0, s, -c - oy], [0.0, 0.0, 1.0]])


def _detail_matrix(look: Look, level: int) -> np.ndarray:
    s = DETAIL_TEXEL_M * 2**level
    ox, oy = look.world_offset
    return np.array([[s, 0.0, -ox], [0.0, s, -oy], [0.0, 0.0, 1.0]])


def _placement(tex: np.ndarray, M: np.ndarray, box, period: int = 0) -> tuple[np.ndarray, int]:
    """Texel → ground matrix and border mode for warping the part of ``tex`` that ground box ``box`` needs.

    ``M`` maps texel coordinates of ``tex`` to ground metres (axis-aligned scale and offset); ``box = (xmin, xmax,
    ymin, ymax)`` in metres. OpenCV's warps take a slow path for every pixel that samples outside the source
    unless the border is constant, so: a repeating texture (``period`` > 0 texels; ``tex`` holds whole periods) is
    shifted by whole periods to put the box inside it when it fits, and a non-repeating one gets a constant border
    when the box is inside it, else reflection (BORDER_REFLECT_101) beyond its edges.
    """
    j0, j1 = math.floor((box[0] - M[0, 2]) / M[0, 0]) - 1, math.ceil((box[1] - M[0, 2]) / M[0, 0]) + 1
    i0, i1 = math.floor((box[2] - M[1, 2]) / M[1, 1]) - 1, math.ceil((box[3] - M[1, 2]) / M[1, 1]) + 1
    h, w = tex.shape[:2]
    if period:
        sj, si = j0 - j0 % period, i0 - i0 % period
        M = M @ np.array([[1.0, 0.0, sj], [0.0, 1.0, si], [0.0, 0.0, 1.0]])
        j0, j1, i0, i1 = j0 - sj, j1 - sj, i0 - si, i1 - si
    if 0 <= j0 and j1 < w and 0 <= i0 and i1 < h:
        return M, cv2.BORDER_CONSTANT
    return M, cv2.BORDER_WRAP if period else cv2.BORDER_REFLECT_101


def _chunks(sel: np.ndarray, box: np.ndarray, width_cells: int, height_cells: int) -> list[tuple]:
    """Blocks covering ``sel`` (gh, gw): ``(r0, r1, c0, c1, (xmin, xmax, ymin, ymax))`` per non-empty block.

    The frame is cut into blocks of ``height_cells × width_cells`` cells; ``r0:r1, c0:c1`` is the tight cell box of
    the block's selected cells (tight for tilted stripes) and the last item bounds their ground boxes (``box``
    (4, gh, gw), :class:`.grid.Grid`). Computed for all blocks at once.
    """
    gh, gw = sel.shape
    any_row = np.flatnonzero(sel.any(axis=1))
    if not any_row.size:
        return []
    ra = int(any_row[0])
    nr = -(-(int(any_row[-1]) + 1 - ra) // height_cells)
    nc = -(-gw // width_cells)
    rb = ra + nr * height_cells
    pad = ((0, max(0, rb - gh)), (0, nc * width_cells - gw))
    s4 = np.pad(sel[ra:rb], pad).reshape(nr, height_cells, nc, width_cells)
    rows = s4.any(axis=3)  # (nr, height, nc)
    cols = s4.any(axis=1)  # (nr, nc, width)
    base_r = ra + np.arange(nr)[:, None] * height_cells
    r0 = base_r + rows.argmax(axis=1)
    r1 = base_r + height_cells - rows[:, ::-1].argmax(axis=1)
    base_c = np.arange(nc)[None, :] * width_cells
    c0 = base_c + cols.argmax(axis=2)
    c1 = base_c + width_cells - cols[:, :, ::-1].argmax(axis=2)
    # ground boxes: lower bounds (xmin, ymin) where selected else +inf, upper bounds likewise with −inf
    b6 = np.pad(box[:, ra:rb], ((0, 0), *pad)).reshape(4, nr, height_cells, nc, width_cells)
    lo = np.where(s4, b6[0::2], np.inf).min(axis=(2, 4))  # (2, nr, nc)
    hi = np.where(s4, b6[1::2], -np.inf).max(axis=(2, 4))
    return [(int(r0[i, j]), int(r1[i, j]), int(c0[i, j]), int(c1[i, j]),
             (float(lo[0, i, j]), float(hi[0, i, j]), float(lo[1, i, j]), float(hi[1, i, j])))
            for i, j in zip(*np.nonzero(rows.any(axis=1)), strict=True)]


def _warp(src: np.ndarray, M: np.ndarray, size: tuple[int, int], mode: int = cv2.BORDER_CONSTANT,
          value=0) -> np.ndarray:
    """Bilinear ``cv2.warpPerspective`` of ``src`` by ``M`` (source → destination)."""
    return cv2.warpPerspective(src, M, size, flags=cv2.INTER_LINEAR, borderMode=mode, borderValue=value)


def _warp_smooth(src: np.ndarray, M: np.ndarray, size: tuple[int, int], mode: int, value, q: int) -> np.ndarray:
    """:func:`_warp` computed on a grid ``q`` times coarser and bilinearly upsampled (for strongly magnified sources).

    Low-resolution pixel ``x_l`` sits at full-resolution ``q·x_l + (q − 1)/2`` (the convention of ``cv2.resize``),
    with one extra low-resolution pixel on every side so that the upsampling never extrapolates at the edges.
    """
    if q == 1:
        return _warp(src, M, size, mode, value)
    wl, hl = -(-size[0] // q) + 2, -(-size[1] // q) + 2
    to_low = np.array([[1.0 / q, 0.0, 1.0 - (q - 1) / (2.0 * q)], [0.0, 1.0 / q, 1.0 - (q - 1) / (2.0 * q)],
                       [0.0, 0.0, 1.0]])
    low = _warp(src, to_low @ M, (wl, hl), mode, value)
    up = cv2.resize(low, (wl * q, hl * q), interpolation=cv2.INTER_LINEAR)
    return up[q:q + size[1], q:q + size[0]]


def _shade_chunk(world: np.ndarray, rgba: np.ndarray | None, hz: np.ndarray, detail: tuple, Md: np.ndarray,
                 box: tuple, HT: np.ndarray, size: tuple[int, int], amp_w: float, amp_t: float, noise_lut: np.ndarray,
                 gain: list) -> np.ndarray:
    """One chunk's colour (float32 RGBA) of :func:`_render_ground`: the warped ``world`` raster under the airport
    tile ``rgba`` (None where the chunk does not see the airport), with detail noise (``detail`` = a level of
    :func:`.textures.detail_tiles`), the ground gain and the chunk's haze ``hz``."""
    # per-pixel weights (one channel): f = transmittance × detail, a1 = f × (1 − airport coverage)
    f = hz[..., 3].copy()
    if amp_w > 0:
        Mp, mode = _placement(detail[0], Md, box, period=detail[1])
        d8 = _warp(detail[0], HT @ Mp, size, mode, 128)
        if rgba is not None:  # 1 + noise·(amp_w + (amp_t − amp_w)·coverage)
            det = cv2.LUT(d8, noise_lut)
            amp = rgba[..., 3] * np.float32(amp_t - amp_w)
            amp += np.float32(amp_w)
            det *= amp
            det += 1.0
        else:
            det = cv2.LUT(d8, 1.0 + np.float32(amp_w) * noise_lut)
        det *= f
        f = det
    if rgba is not None:
        a1 = 1.0 - rgba[..., 3]
        a1 *= f
    else:
        a1 = f
    # (OpenCV multiplies and adds 4-channel images by 1-channel maps much faster than numpy broadcasts)
    col = cv2.multiply(world, cv2.merge([a1 * gain[0], a1 * gain[1], a1 * gain[2], a1]), dtype=cv2.CV_32F)
    if rgba is not None:
        cv2.add(col, cv2.multiply(rgba, cv2.cvtColor(f, cv2.COLOR_GRAY2RGBA), dst=rgba), dst=col)
    cv2.add(col, hz, dst=col)  # (adds w to the unused A)
    return col


def _render_ground(H: np.ndarray, layout: np.ndarray, look: Look, g: Grid, r_max: float, out: np.ndarray,
                   haze: np.ndarray | None) -> None:
    """Draw the ground cells within ``r_max`` into ``out`` (height, width, 4) uint8 (RGB, A unused), band by band.

    ``haze`` (height, width, 4) float32: in-scattered light ``hz = sky·(1 − w)`` (RGB) and the ground's
    transmittance ``w`` (A), so that a pixel is ``albedo·light·w + hz`` (None for debug renders).
    """
    height, width = out.shape[:2]
    S = STRIDE
    valid = g.ground & (g.rng_m < r_max)
    if not valid.any():
        return
    level = np.where(valid, np.floor(np.log2(np.maximum(g.iso, MIN_TEXEL_M) / MIN_TEXEL_M)), -1).astype(np.int32)
    bands = {int(k): level == k for k in np.unique(level[level >= 0])}
    tiles = airport_tiles(layout, g, bands, (1.0, 1.0, 1.0) if look.debug else look.ground_gain)
    if not look.debug:
        pyr = world_pyramid(look.world)
        dpyr = detail_tiles()
        gain = [np.float32(c / 255.0) for c in look.ground_gain]
        border = (*(int(round(255.0 * c)) for c in world_mean(look.world)), 0)
        noise_lut = ((np.arange(256, dtype=np.float32) - 128.0) / np.float32(DETAIL_Q)).reshape(1, 256)
    for k, sel in bands.items():
        iso_min = float(g.iso[sel].min())
        band_tile = tiles.get(k)
        if look.debug and band_tile is None:
            continue
        if band_tile is not None:  # the tile's ground extent (texel edges)
            (ny, nx), A = band_tile[0].shape[:2], band_tile[1]
            tx0, ty0 = A[0, 2] - A[0, 0] / 2, A[1, 2] - A[1, 1] / 2
            tile_box = (tx0, tx0 + nx * A[0, 0], ty0, ty0 + ny * A[1, 1])
        if not look.debug:
            m = int(np.clip(math.floor(math.log2(max(iso_min, WORLD_TEXEL_M) / WORLD_TEXEL_M)), 0, len(pyr) - 1))
            Mw = _world_matrix(look, m)
            amp_w = look.detail_amp * max(0.0, min(1.0, 2 * WORLD_TEXEL_M / iso_min - 1.0))
            amp_t = TILE_DETAIL_GAIN * look.detail_amp  # (none beyond twice the world texel: it would only alias)
            dl = int(np.clip(math.floor(math.log2(max(iso_min, DETAIL_TEXEL_M) / DETAIL_TEXEL_M)), 0, len(dpyr) - 1))
            Md = _detail_matrix(look, dl)
            # the world raster magnified 4× or more is smooth at the pixel scale: warp it at 1/q resolution
            iso_max = float(g.iso[sel].max())
            q = 4 if iso_max * 8 <= WORLD_TEXEL_M else 2 if iso_max * 4 <= WORLD_TEXEL_M else 1
        for r0, r1, c0, c1, box in _chunks(sel, g.box, CHUNK_CELLS, CHUNK_ROWS):
            v0, v1, u0, u1 = r0 * S, min(r1 * S, height), c0 * S, min(c1 * S, width)
            size = (u1 - u0, v1 - v0)
            HT = H - np.outer((u0, v0, 0.0), H[2])  # ground → chunk pixels
            cells = sel[r0:r1, c0:c1]
            tile = band_tile
            if tile is not None and (box[1] < tile_box[0] or box[0] > tile_box[1] or box[3] < tile_box[2]
                                     or box[2] > tile_box[3]):
                tile = None  # this block does not see the airport
                if look.debug:
                    continue
            if tile is not None:
                rgba = _warp(tile[0], HT @ tile[1], size)
            if look.debug:
                col = rgba
            else:
                Mp, mode = _placement(pyr[m], Mw, box)
                world = _warp_smooth(pyr[m], HT @ Mp, size, mode, border, q)
                col = _shade_chunk(world, rgba if tile is not None else None, haze[v0:v1, u0:u1], dpyr[dl], Md, box,
                                   HT, size, amp_w, amp_t, noise_lut, gain)
            col8 = cv2.convertScaleAbs(col, alpha=255.0)  # rounds and saturates to uint8 (values are >= 0)
            if cells.all():
                out[v0:v1, u0:u1] = col8
            else:
                mask = cv2.resize(cells.view(np.uint8), ((c1 - c0) * S, (r1 - r0) * S), interpolation=cv2.INTER_NEAREST)
                cv2.copyTo(col8, mask[: v1 - v0, : u1 - u0], out[v0:v1, u0:u1])


def _sky_and_weight(look: Look, g: Grid) -> tuple[np.ndarray, np.ndarray]:
    """Coarse sky/haze colour (gh, gw, 3) and ground weight ``transmittance`` (gh, gw), float32."""
    dx, dy, dz = g.d
    inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
    el = np.clip(dz * inv, 0.0, 1.0)
    mix = 1.0 - np.exp(el * (-1.0 / 0.12))
    sx, sy, sz = look.sun_dir
    cosg = (dx * sx + dy * sy + dz * sz) * inv - 1.0
    glow = 0.9 * np.exp(cosg * (1.0 / 0.0015)) + 0.25 * np.exp(cosg * (1.0 / 0.06))
    sky = np.empty(dz.shape + (3,), np.float32)
    for i, (zc, hc, sc) in enumerate(zip(look.sky_zenith, look.sky_horizon, look.sun_rgb, strict=True)):
        sky[..., i] = hc + (zc - hc) * mix + sc * glow
    with np.errstate(invalid="ignore"):
        w = np.where(g.ground, np.exp(-g.rng_m / look.visibility_m), 0.0)
    return sky, w.astype(np.float32)


def _upsample(a: np.ndarray, width: int, height: int, r0: int = 0, r1: int | None = None) -> np.ndarray:
    """Bilinear upsampling of a coarse-grid map whose samples sit at cell centres (STRIDE·k + (STRIDE−1)/2).

    Only the pixel rows of cell rows ``r0:r1`` (same values as upsampling everything and cropping).
    """
    gh, gw = a.shape[:2]
    r1 = gh if r1 is None else r1
    pad = cv2.copyMakeBorder(a[max(r0 - 1, 0):r1 + 1], int(r0 == 0), int(r1 == gh), 0, 0, cv2.BORDER_REPLICATE)
    up = cv2.resize(pad, (gw * STRIDE, pad.shape[0] * STRIDE), interpolation=cv2.INTER_LINEAR)
    return up[STRIDE:STRIDE + min((r1 - r0) * STRIDE, height - r0 * STRIDE), :width]


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
    H = ground_homography(R, C, K)
    r_max = min(6.0 * look.visibility_m, MAX_RANGE_M)
    g = make_grid(R, C, K, width, height, STRIDE, clip_m=CLIP_FACTOR * r_max)
    if look.debug:
        img4 = np.zeros((height, width, 4), np.uint8)
        _render_ground(H, layout, look, g, r_max, img4, None)
        return cv2.cvtColor(img4, cv2.COLOR_RGBA2RGB)
    sky, w = _sky_and_weight(look, g)
    hz = sky * (1.0 - w[..., None])
    # pixels that no band draws (sky, ground beyond r_max) show the world's mean colour through the haze; only
    # their rows are upsampled (every other pixel is drawn over)
    img4 = np.empty((height, width, 4), np.uint8)
    rows = np.flatnonzero(~(g.ground & (g.rng_m < r_max)).all(axis=1))
    if rows.size:
        mean = world_mean(look.world) * np.asarray(look.ground_gain, np.float32)
        bg = cv2.convertScaleAbs(np.dstack([hz + w[..., None] * mean, w]), alpha=255.0)
        r0, r1 = int(rows[0]), int(rows[-1]) + 1
        img4[r0 * STRIDE:r1 * STRIDE] = _upsample(bg, width, height, r0, r1)
    _render_ground(H, layout, look, g, r_max, img4, _upsample(np.dstack([hz, w]), width, height))
    img8 = cv2.cvtColor(img4, cv2.COLOR_RGBA2RGB)
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
