"""Airport tiles: the layout painted at the ground footprint of each footprint band of a frame.

The renderer draws the ground band by band (cells grouped by ``log2`` of their pixel footprint, see
:mod:`.render`). Each band that sees the airport gets a premultiplied RGBA tile whose texel size is the smallest
footprint of the band along each runway axis, so it is never minified by more than about 2× (and never
magnified), and whose texels hold exact area coverage (:func:`.layout.paint`).
"""

from __future__ import annotations

import math

import numpy as np

from .grid import Grid
from .layout import paint

#: Smallest texel size (metres) of a tile.
MIN_TEXEL_M = 0.02
#: Largest tile (texels); beyond it the texel size grows (only far, hazy bands ever reach it).
MAX_TILE_TEXELS = 1_500_000
#: Largest tile side (OpenCV warps need < 32767).
MAX_TILE_SIDE = 8192

Region = tuple[float, float, float, float]  # (xmin, xmax, ymin, ymax), metres, runway frame


def layout_bounds(layout: np.ndarray) -> Region:
    """Ground box of all layout rows."""
    return (float(layout[:, 0].min()), float(layout[:, 1].max()), float(layout[:, 4].min()),
            float(layout[:, 5].max()))


def band_region(g: Grid, sel: np.ndarray, bounds: Region) -> tuple[Region, float, float] | None:
    """Ground region of the layout seen by the cells ``sel`` (with a 2-texel margin) and the texel size (sx, sy)."""
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
    return (xmin, xmax, ymin, ymax), sx, sy


def paint_tile(layout: np.ndarray, region: Region, sx: float, sy: float, gain) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied RGBA tile (ny, nx, 4) float32 of the lit layout over ``region`` and its texel → ground matrix.

    Texel ``(i, j)`` is centred at ``(xmin + j·sx, ymin + i·sy)``; the texel size grows when the tile would exceed
    :data:`MAX_TILE_TEXELS` or :data:`MAX_TILE_SIDE`.
    """
    xmin, xmax, ymin, ymax = region
    nx, ny = (xmax - xmin) / sx + 1, (ymax - ymin) / sy + 1
    scale = max(1.0, math.sqrt(nx * ny / MAX_TILE_TEXELS), nx / MAX_TILE_SIDE, ny / MAX_TILE_SIDE)
    sx, sy = sx * scale, sy * scale
    nx, ny = int((xmax - xmin) / sx) + 2, int((ymax - ymin) / sy) + 2
    tile = np.zeros((ny, nx, 4), np.float32)
    paint(tile, xmin, ymin, sx, sy, layout, gain=gain, blank=True)
    return tile, np.array([[sx, 0.0, xmin], [0.0, sy, ymin], [0.0, 0.0, 1.0]])


def airport_tiles(layout: np.ndarray, g: Grid, bands: dict[int, np.ndarray], gain) -> dict[int, tuple]:
    """Tile and matrix ``(tile, A)`` (:func:`paint_tile`) for every band (level → cell mask) that sees the layout."""
    bounds = layout_bounds(layout)
    out = {}
    for k, sel in bands.items():
        spec = band_region(g, sel, bounds)
        if spec is not None:
            out[k] = paint_tile(layout, *spec, gain)
    return out
