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

    d: np.ndarray  # (gh, gw, 3) ray directions in the runway frame (forward component 1 in the camera)
    ground: np.ndarray  # bool, ray hits the ground
    gx: np.ndarray
    gy: np.ndarray
    rng_m: np.ndarray  # range to the ground hit (inf where none)
    fx: np.ndarray  # ground footprint of a pixel along runway x / y, metres
    fy: np.ndarray
    iso: np.ndarray  # sqrt of the ground area of a pixel, metres
    box: np.ndarray  # (4, gh, gw) bounding box (xmin, xmax, ymin, ymax) of the cell's ground region ∩ the clip disk


def hits(R, C, K, u: np.ndarray, v: np.ndarray):
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


def _four(a: np.ndarray) -> np.ndarray:
    """The four cell-corner values (4, gh, gw) of a (gh + 1, gw + 1) corner array."""
    return np.stack([a[:-1, :-1], a[1:, :-1], a[:-1, 1:], a[1:, 1:]])


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
    d, ground, gx, gy, rng_m, fx, fy, iso = hits(R, C, K, u, v)
    # cell corners: their ground hits bound each cell's ground region and their footprints bound the footprints
    # inside the cell from below (near the horizon the footprint changes by large factors within one cell)
    uc = stride * np.arange(gw + 1) - 0.5
    vc = stride * np.arange(gh + 1) - 0.5
    dc, gc, cx, cy, _, cfx, cfy, _ = hits(R, C, K, uc, vc)
    with np.errstate(invalid="ignore"):
        near = gc & (np.hypot(cx - C[0], cy - C[1]) <= clip_m)
    hn = np.hypot(dc[..., 0], dc[..., 1])
    hn = np.where(hn > 0, hn, 1.0)
    far_x = C[0] + clip_m * dc[..., 0] / hn  # where each corner's horizontal direction leaves the clip disk
    far_y = C[1] + clip_m * dc[..., 1] / hn
    closed = _four(near).all(axis=0)  # the cell's ground region is the quad of its corner hits
    px4, py4 = _four(np.where(near, cx, far_x)), _four(np.where(near, cy, far_y))
    fx4, fy4 = _four(far_x), _four(far_y)
    # an open cell also spans the arc between its corner directions
    pad = np.where(closed, 0.0, 1e-3 * clip_m)
    box = np.stack([
        np.minimum(px4.min(axis=0), np.where(closed, np.inf, fx4.min(axis=0))) - pad,
        np.maximum(px4.max(axis=0), np.where(closed, -np.inf, fx4.max(axis=0))) + pad,
        np.minimum(py4.min(axis=0), np.where(closed, np.inf, fy4.min(axis=0))) - pad,
        np.maximum(py4.max(axis=0), np.where(closed, -np.inf, fy4.max(axis=0))) + pad,
    ])
    fx = np.minimum(fx, _four(cfx).min(axis=0))
    fy = np.minimum(fy, _four(cfy).min(axis=0))
    return Grid(d, ground, gx, gy, rng_m, fx, fy, iso, box)
