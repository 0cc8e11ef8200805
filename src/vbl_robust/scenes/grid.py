"""Per-pixel ground geometry of a frame, sampled on a coarse grid of cells (every ``stride`` pixels).

For each cell: the ray of its centre (runway frame), whether it hits the ground plane ``z = 0`` (only rays
pointing down: nothing behind the camera or above the horizon is ever mapped to the ground, so the plane cannot
"wrap"), the range of the hit, the ground footprint of one pixel along the runway axes (the Jacobian of the
inverse homography) and a bounding box of the cell's ground region, clipped to a horizontal radius around the
camera so that cells at the horizon get finite boxes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Grid:
    """Per-cell geometry on the coarse grid (arrays of shape (gh, gw))."""

    d: np.ndarray  # (3, gh, gw) ray directions in the runway frame (forward component 1 in the camera)
    ground: np.ndarray  # bool, ray hits the ground
    rng_m: np.ndarray  # range to the ground hit (inf where none)
    fx: np.ndarray  # ground footprint of a pixel along runway x / y, metres
    fy: np.ndarray
    iso: np.ndarray  # sqrt of the ground area of a pixel, metres
    box: np.ndarray  # (4, gh, gw) bounding box (xmin, xmax, ymin, ymax) of the cell's ground region ∩ the clip disk


def hits(R, C, K, u: np.ndarray, v: np.ndarray):
    """Rays through pixels ``(u[j], v[i])`` (shapes (len(v), len(u))).

    Returns the direction components ``(dx, dy, dz)`` in the runway frame, the ground mask, the ground hit ``x, y`` (metres), the
    distance ``t`` along the ray to the hit (range = ``t·|d|``; inf where the ray misses the ground), the footprint
    of one pixel along runway x and y (``fx, fy``: largest Jacobian entry of the row) and ``iso``, the square root
    of the pixel's ground area.
    """
    R = np.asarray(R, dtype=np.float64)
    du = -R[:, 1] / K[0, 0]
    dv = -R[:, 2] / K[1, 1]
    d0 = R[:, 0] - du * K[0, 2] - dv * K[1, 2]
    dx, dy, dz = (np.add.outer(v * dv[i], d0[i] + u * du[i]) for i in range(3))
    ground = dz < -1e-9
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.where(ground, -C[2] / dz, np.inf)
        gx = C[0] + t * dx
        gy = C[1] + t * dy
        k = t / dz  # = −C_z / dz² (negated below)
        a = k * (dx * du[2] - du[0] * dz)  # d gx / du
        b = k * (dx * dv[2] - dv[0] * dz)  # d gx / dv
        c = k * (dy * du[2] - du[1] * dz)  # d gy / du
        e = k * (dy * dv[2] - dv[1] * dz)  # d gy / dv
        iso = np.sqrt(np.abs(a * e - b * c))
        fx = np.where(ground, np.maximum(np.abs(a), np.abs(b)), np.inf)
        fy = np.where(ground, np.maximum(np.abs(c), np.abs(e)), np.inf)
    d = (dx, dy, dz)
    return d, ground, gx, gy, t, fx, fy, iso


def _min4(a: np.ndarray) -> np.ndarray:
    """Smallest of the four cell-corner values (gh, gw) of a (gh + 1, gw + 1) corner array."""
    return np.minimum(np.minimum(a[:-1, :-1], a[1:, :-1]), np.minimum(a[:-1, 1:], a[1:, 1:]))


def _max4(a: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(a[:-1, :-1], a[1:, :-1]), np.maximum(a[:-1, 1:], a[1:, 1:]))


def make_grid(R, C, K, width: int, height: int, stride: int, clip_m: float) -> Grid:
    """Geometry of the ``stride``-pixel cells of a ``width × height`` frame (cell centres at ``stride·k + (stride−1)/2``).

    ``clip_m`` (metres, horizontal, around the camera) bounds the boxes of cells that reach the horizon or beyond
    it: such a box covers the ground hits of the cell's corners within ``clip_m`` and the points at ``clip_m`` in
    the horizontal directions of all four corner rays (the cell's ground region inside the clip disk lies in their
    hull, up to the arc's sagitta, which a relative margin of 1e-3 covers for cells narrower than 5°).
    """
    C = np.asarray(C, dtype=np.float64)
    gw, gh = -(-width // stride), -(-height // stride)
    u = stride * np.arange(gw) + (stride - 1) / 2.0
    v = stride * np.arange(gh) + (stride - 1) / 2.0
    (dx, dy, dz), ground, _, _, t, fx, fy, iso = hits(R, C, K, u, v)
    with np.errstate(invalid="ignore"):
        rng_m = t * np.sqrt(dx * dx + dy * dy + dz * dz)
    # cell corners: their ground hits bound each cell's ground region and their footprints bound the footprints
    # inside the cell from below (near the horizon the footprint changes by large factors within one cell)
    uc = stride * np.arange(gw + 1) - 0.5
    vc = stride * np.arange(gh + 1) - 0.5
    dc, gc, cx, cy, _, cfx, cfy, _ = hits(R, C, K, uc, vc)
    hn = np.hypot(dc[0], dc[1])
    with np.errstate(invalid="ignore"):
        near = gc & (np.hypot(cx - C[0], cy - C[1]) <= clip_m)
    hn = np.where(hn > 0, clip_m / np.where(hn > 0, hn, 1.0), 0.0)
    far_x = C[0] + hn * dc[0]  # where each corner's horizontal direction leaves the clip disk
    far_y = C[1] + hn * dc[1]
    px, py = np.where(near, cx, far_x), np.where(near, cy, far_y)
    open_ = ~(near[:-1, :-1] & near[1:, :-1] & near[:-1, 1:] & near[1:, 1:])  # not just the quad of corner hits
    # an open cell also spans the arc between its corner directions (padded by its sagitta)
    pad = 1e-3 * clip_m
    box = np.stack([_min4(px), _max4(px), _min4(py), _max4(py)])
    if open_.any():
        arc = np.stack([_min4(far_x) - pad, _max4(far_x) + pad, _min4(far_y) - pad, _max4(far_y) + pad])
        box[0::2] = np.where(open_, np.minimum(box[0::2], arc[0::2]), box[0::2])
        box[1::2] = np.where(open_, np.maximum(box[1::2], arc[1::2]), box[1::2])
    fx = np.minimum(fx, _min4(cfx))
    fy = np.minimum(fy, _min4(cfy))
    return Grid(np.stack([dx, dy, dz]), ground, rng_m, fx, fy, iso, box)
