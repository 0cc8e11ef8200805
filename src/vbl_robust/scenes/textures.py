"""Procedural textures shared by all scenes (built lazily, once per process, from fixed seeds, then cached).

* **World rasters** (:func:`world_pyramid`): a few 16 km × 16 km albedo maps at 8 m/texel — a patchwork of
  fields with hedges, forests, lakes, villages and roads — with a Gaussian pyramid for minification whose coarse
  levels are extended by reflection (:func:`world_pad`). About 0.5 s and 36 MB each, built on first use.
* **Detail noise** (:func:`detail_pyramid`): a tileable 1/f noise at 0.1 m/texel (period 51.2 m) and its box
  pyramid, multiplied into the ground at texel sizes below the world raster's; :func:`detail_tiles` holds it as
  repeated uint8 textures for the warps.
* **Sensor noise** (:func:`sensor_noise`): a fixed buffer of Gaussian noise; images take random crops of it, which
  is much cheaper than drawing fresh normal numbers for every pixel.

Everything is deterministic (fixed seeds), so cached or not, a scene renders to the same pixels.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np

N_WORLDS = 4
WORLD_SIZE = 2048
WORLD_TEXEL_M = 8.0
WORLD_REACH_M = 40_000.0
WORLD_PADDED_MAX = 1280
DETAIL_SIZE = 512
DETAIL_TEXEL_M = 0.1
DETAIL_TILED = 1024
DETAIL_Q = 28.0
SENSOR_NOISE_STD = 16.0

_PALETTE = np.array([
    (0.20, 0.30, 0.12), (0.25, 0.35, 0.15), (0.30, 0.38, 0.18), (0.38, 0.45, 0.22),  # greens
    (0.55, 0.50, 0.30), (0.62, 0.55, 0.36), (0.50, 0.44, 0.26),  # cereal / stubble
    (0.40, 0.32, 0.22), (0.33, 0.27, 0.20), (0.46, 0.38, 0.28),  # bare soil
    (0.15, 0.22, 0.10),  # dark green
], dtype=np.float32)


def fft_noise(rng: np.random.Generator, n: int, beta: float, n_out: int | None = None) -> np.ndarray:
    """Tileable (n, n) float32 noise with power spectrum ∝ 1/f^(2·beta), zero mean, unit std.

    With ``n_out`` the noise is made at ``n`` and upsampled (bicubic) to ``n_out`` (cheap low-frequency noise).
    """
    white = rng.standard_normal((n, n), dtype=np.float32)
    f = np.fft.fftfreq(n).astype(np.float32)
    rad = np.sqrt(f[:, None] ** 2 + np.fft.rfftfreq(n).astype(np.float32)[None, :] ** 2)
    rad[0, 0] = 1.0
    spec = np.fft.rfft2(white)
    spec *= rad ** np.float32(-beta)
    spec[0, 0] = 0.0
    out = np.fft.irfft2(spec, s=(n, n)).astype(np.float32)
    out /= out.std()
    if n_out is not None and n_out != n:
        out = cv2.resize(out, (n_out, n_out), interpolation=cv2.INTER_CUBIC)
    return out


def _mask_above(noise: np.ndarray, q: float, n: int) -> np.ndarray:
    """``noise`` (a low-resolution field) upsampled to (n, n), above its quantile ``q`` (taken before upsampling)."""
    level = np.quantile(noise, q)
    return cv2.resize(noise, (n, n), interpolation=cv2.INTER_CUBIC) > level


def _world(index: int) -> np.ndarray:
    """(WORLD_SIZE, WORLD_SIZE, 3) uint8 RGB albedo raster ``index`` (deterministic)."""
    rng = np.random.default_rng(10_000 + index)
    n, s = WORLD_SIZE, WORLD_TEXEL_M
    coords = (np.arange(n, dtype=np.float32) - (n - 1) / 2) * s
    theta = rng.uniform(0, np.pi)
    ca, sa = np.float32(np.cos(theta)), np.float32(np.sin(theta))
    a = coords[None, :] * ca + coords[:, None] * sa
    b = -coords[None, :] * sa + coords[:, None] * ca
    # parcels: rows of random height, each row cut into columns of its own width and phase
    half = n * s
    row_h = rng.uniform(80.0, 350.0, 400)
    edges = np.cumsum(row_h) - half
    # row of each texel, and whether it is within 5 m of the row's edge, from 1/4-metre lookup tables on b (rows
    # are at least 80 m high; much cheaper than searching every texel)
    b_min = float(b.min())
    bq = b_min + (np.arange(int((float(b.max()) - b_min) * 4) + 2) + 0.5) / 4
    r_table = np.searchsorted(edges, bq)
    e_lo = np.concatenate([[-np.inf], edges])[r_table]
    e_hi = np.concatenate([edges, [np.inf]])[r_table]
    idx = ((b - np.float32(b_min)) * np.float32(4)).astype(np.int32)
    r = r_table.astype(np.int32)[idx]
    near_row_edge = (np.minimum(bq - e_lo, e_hi - bq) < 5.0)[idx]
    col_w = rng.uniform(80.0, 500.0, len(edges) + 1).astype(np.float32)
    col_off = rng.uniform(0.0, 500.0, len(edges) + 1).astype(np.float32)
    cw = col_w[r]
    cpos = a - col_off[r]
    cpos /= cw
    c = np.floor(cpos)
    frac = cpos - c
    # parcel id: a hash of (row, column) into 2^16 values (uint32 arithmetic wraps around)
    pid = ((r.astype(np.uint32) * np.uint32(73856093)) ^ (c.astype(np.int32).view(np.uint32) * np.uint32(19349663)))
    pid &= np.uint32(0xFFFF)
    weights = rng.dirichlet(np.full(len(_PALETTE), 0.8))
    lut = rng.choice(len(_PALETTE), size=65536, p=weights)
    bright = rng.uniform(0.85, 1.15, 65536).astype(np.float32)
    # hedges / tracks along some parcel borders: one colour table for plain and hedged parcels, one gather
    colours = _PALETTE[lut] * bright[:, None]
    colours = np.concatenate([colours, colours * 0.6 + np.float32([0.12, 0.16, 0.08]) * 0.4])
    border = (np.minimum(frac, 1 - frac) * cw < 5.0) | near_row_edge
    pid += np.uint32(65536) * (border & (bright[pid] > 0.95))
    img = colours[pid]
    flat = img.reshape(-1, 3)
    # forests, lakes, villages from low-frequency noise
    forest = fft_noise(rng, 512, 1.6)
    fine = fft_noise(rng, 1024, 0.6, n).reshape(-1)
    idx = np.flatnonzero(_mask_above(forest, 0.86, n))
    flat[idx] = np.float32([0.10, 0.17, 0.08]) * (1.0 + 0.25 * fine[idx])[:, None]
    lake = fft_noise(rng, 512, 1.8)
    flat[np.flatnonzero(_mask_above(lake, 0.985, n))] = np.float32([0.10, 0.14, 0.17])
    town = fft_noise(rng, 512, 1.7)
    idx = np.flatnonzero(_mask_above(town, 0.965, n))
    roofs = np.float32([[0.45, 0.42, 0.40], [0.55, 0.30, 0.22], [0.60, 0.60, 0.58], [0.30, 0.30, 0.30]])
    flat[idx] = roofs[rng.integers(0, 4, idx.size)]
    light = fft_noise(rng, 512, 1.2, n)
    light *= np.float32(0.08 * 255.0)
    light += np.float32(255.0)
    out = cv2.convertScaleAbs(cv2.multiply(img, cv2.cvtColor(light, cv2.COLOR_GRAY2RGB)))
    for _ in range(int(rng.integers(4, 9))):  # roads
        p = rng.uniform(0, n, 2)
        ang = rng.uniform(0, np.pi)
        d = np.array([np.cos(ang), np.sin(ang)]) * 2 * n
        col = (np.array([0.36, 0.36, 0.35]) * 255 * rng.uniform(0.8, 1.3)).tolist()
        cv2.line(out, tuple(int(v) for v in p - d), tuple(int(v) for v in p + d), col,
                 int(rng.integers(1, 3)), cv2.LINE_AA)
    return out


@functools.lru_cache(maxsize=N_WORLDS)
def world_pyramid(index: int) -> tuple[np.ndarray, ...]:
    """Gaussian pyramid of world raster ``index``: uint8 RGBA (albedo, A = 255); level m has texel ``8·2^m`` m.

    Four channels because OpenCV's bilinear warps have a vectorised path for 1 and 4 channels, not for 3.
    """
    levels = [cv2.cvtColor(_world(int(index) % N_WORLDS), cv2.COLOR_RGB2RGBA)]
    while levels[-1].shape[0] > 32:
        levels.append(cv2.pyrDown(levels[-1], borderType=cv2.BORDER_REFLECT_101))
    out = []
    for m, x in enumerate(levels):
        p = world_pad(m)
        out.append(cv2.copyMakeBorder(x, p, p, p, p, cv2.BORDER_REFLECT_101) if p else x)
    return tuple(out)


def world_pad(level: int) -> int:
    """Texels added by reflection on each side of world pyramid level ``level`` (0 for the two finest levels).

    Coarse levels are drawn up to the horizon, far beyond the raster; extending them here (up to
    :data:`WORLD_REACH_M` from the centre, at most :data:`WORLD_PADDED_MAX` texels a side) lets the renderer warp
    them with a constant border, which OpenCV does much faster than reflecting at run time.
    """
    if level < 2:
        return 0
    n = WORLD_SIZE >> level
    want = math.ceil(WORLD_REACH_M / (WORLD_TEXEL_M * 2**level)) - n // 2
    return int(max(0, min(want, (WORLD_PADDED_MAX - n) // 2)))


def world_mean(index: int) -> np.ndarray:
    """(3,) float32 mean albedo (RGB in [0, 1]) of world raster ``index``."""
    return world_pyramid(index)[-1][..., :3].reshape(-1, 3).mean(axis=0).astype(np.float32) / np.float32(255.0)


@functools.lru_cache(maxsize=1)
def detail_pyramid() -> tuple[np.ndarray, ...]:
    """Box pyramid of the tileable detail noise (float32, std 1 at level 0); level l has texel ``0.1·2^l`` m."""
    base = fft_noise(np.random.default_rng(20_000), DETAIL_SIZE, 0.9)
    levels = [base]
    while levels[-1].shape[0] > 8:
        x = levels[-1]
        levels.append(0.25 * (x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2]))
    return tuple(levels)


@functools.lru_cache(maxsize=1)
def detail_tiles() -> tuple[tuple[np.ndarray, int], ...]:
    """The detail pyramid's levels as uint8 ``128 + DETAIL_Q·noise``, repeated to :data:`DETAIL_TILED` texels a side.

    Returns ``(texture, period)`` per level. Warps then read a window of whole periods instead of wrapping around
    the border (slow in OpenCV), and uint8 keeps the textures small enough for the caches.
    """
    out = []
    for x in detail_pyramid():
        q = np.clip(np.rint(128.0 + DETAIL_Q * x), 0, 255).astype(np.uint8)
        reps = -(-DETAIL_TILED // x.shape[0])
        out.append((np.ascontiguousarray(np.tile(q, (reps, reps))), x.shape[0]))
    return tuple(out)


@functools.lru_cache(maxsize=4)
def sensor_noise(height: int, width: int) -> np.ndarray:
    """(height + 64, width + 64, 3) uint8 Gaussian noise, mean 128, std :data:`SENSOR_NOISE_STD`."""
    x = np.random.default_rng(30_000).standard_normal((height + 64, (width + 64) * 3), dtype=np.float32)
    # rounds and saturates (nothing reaches −8σ, where the absolute value would matter)
    return cv2.convertScaleAbs(x, alpha=SENSOR_NOISE_STD, beta=128.0).reshape(height + 64, width + 64, 3)
