"""Views without a gradient on the CPU: one OpenCV warp per view at the exact map (the black-box path).

:class:`~vbl_robust.perturb.views.ViewSampler` samples a view of ``T(x; θ)`` by reading the source at the perturbation's
inverse map, reflected into the image (``BORDER_REFLECT_101``) and scaled to the average-pooled source. When the
perturbation's geometry is one homography per θ (:meth:`Perturbation.source_matrices
<vbl_robust.perturb.compose.Perturbation.source_matrices>`; the camera attitude is), a view pixel ``(j, i)`` reads the pooled
source at ``P · H_θ · Q · (j, i, 1)``: ``Q`` maps view pixels to the perturbed frame (:func:`grid_matrix`), ``H_θ``
the frame to the source, ``P`` the source to its pooled copy (:func:`pool_matrix`). So a view is

- every sample inside the source: one ``cv2.warpAffine`` (``cv2.warpPerspective``) with ``BORDER_REPLICATE`` (the
  torch path's border padding of the pooled source). Inside is checked at the grid's four corners, which bound the
  samples of a homography whose ``w`` stays positive over the grid;
- some sample outside: one ``cv2.remap`` at maps reflected in source pixels (the torch path's order: reflect, then
  pool), computed in float64 and stored in float32 relative to the region of the pooled source they read (OpenCV's
  own ``BORDER_REFLECT_101`` warps interpolate at float32 coordinates of the whole image: ~1e-5 px off at 1000 px,
  and slower).

Each warp reads an interleaved copy of the source padded to four channels (one pass over the map for all channels;
OpenCV's four-channel kernels are its fastest), then ``cv2.mixChannels`` writes the planes a network reads. OpenCV ≥
5.1 interpolates in floating point (no 1/32-pixel tables): a view agrees with bilinear sampling at the exact map to
~1e-7, closer than the torch kernel in float32 (its coordinates carry ~1e-4 px of rounding). A view whose map puts
some sample behind the camera (``w ≤ 0``: attitudes beyond ~50°) is left to the torch path.
"""

from __future__ import annotations

import ctypes
import math
import sys
from functools import cached_property, lru_cache

import cv2
import numpy as np
import torch

__all__ = ["PooledSource", "empty_output", "grid_matrix", "pool_matrix", "reflect101_np", "warp_view"]

#: Homogeneous ``w`` at or below which a sample counts as behind the camera (as :mod:`.rotation`).
W_MIN = 1e-9
_LINEAR_INVERSE = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP


_HUGE_PAGE = 2 << 20
_MADV_HUGEPAGE = 14


@lru_cache(maxsize=1)
def _madvise():
    """libc's ``madvise`` on Linux (None elsewhere, or when it cannot be loaded)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        f = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):
        return None
    f.argtypes, f.restype = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int), ctypes.c_int
    return f


def empty_output(*shape: int, dtype=torch.float32) -> torch.Tensor:
    """``torch.empty(shape)`` on the CPU whose whole 2-MiB pages the kernel may back with transparent huge pages
    (``madvise(MADV_HUGEPAGE)``, honoured in the kernel's ``madvise`` and ``always`` modes).

    A batch of 32 views of 320 px is 39 MB: the allocator maps it fresh for each batch, and writing it first costs
    one page fault per 4 KiB page (~10 000 faults, about as long as sampling the views) — 20 with huge pages. Only
    this tensor's memory is advised; its contents are unchanged; nothing happens where ``madvise`` is missing."""
    t = torch.empty(*shape, dtype=dtype)
    f = _madvise()
    nbytes = t.numel() * t.element_size()
    if f is not None and nbytes >= 2 * _HUGE_PAGE:
        start = -(-t.data_ptr() // _HUGE_PAGE) * _HUGE_PAGE
        end = (t.data_ptr() + nbytes) // _HUGE_PAGE * _HUGE_PAGE
        if end > start:
            f(start, end - start, _MADV_HUGEPAGE)  # advice only: a refusal changes nothing
    return t


def grid_matrix(x0, y0, step_x, step_y) -> np.ndarray:
    """``(N, 3, 3)``: view pixel ``(j, i)`` (OpenCV, centres at integers) → OpenCV coordinates of the frame it
    samples, for grids whose edge coordinates start at ``(x0, y0)`` with pixel steps ``step_x``, ``step_y`` (arrays
    ``(N,)``): the pixel centre ``j`` is at edge coordinate ``x0 + (j + ½) · step_x``."""
    x0, y0, sx, sy = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=np.float64))
                                           for a in (x0, y0, step_x, step_y)))
    m = np.zeros((x0.shape[0], 3, 3))
    m[:, 0, 0], m[:, 0, 2] = sx, x0 + 0.5 * sx - 0.5
    m[:, 1, 1], m[:, 1, 2] = sy, y0 + 0.5 * sy - 0.5
    m[:, 2, 2] = 1.0
    return m


def pool_matrix(p: int) -> np.ndarray:
    """``(3, 3)``: source OpenCV pixels → pixels of the source average-pooled by ``p`` (pooled pixel ``k`` covers
    source edges ``[k·p, (k+1)·p)``)."""
    return np.array([[1.0 / p, 0.0, 0.5 / p - 0.5], [0.0, 1.0 / p, 0.5 / p - 0.5], [0.0, 0.0, 1.0]])


def reflect101_np(u, n: int):
    """:func:`~vbl_robust.perturb.views.reflect101` for NumPy arrays or floats (float64)."""
    if n < 2:
        return np.zeros_like(u)
    m = float(n - 1)
    return m - np.abs(np.remainder(u, 2.0 * m) - m)


class PooledSource:
    """The source average-pooled by ``p`` as OpenCV reads it.

    Args:
        planes: ``(C, hp, wp)`` float32, the pooled source (``C`` ≤ 4).
        p: the pooling factor.
        width, height: the unpooled source's size (reflection happens there).
    """

    def __init__(self, planes: np.ndarray, p: int, width: int, height: int) -> None:
        if planes.ndim != 3 or planes.shape[0] > 4 or planes.dtype != np.float32:
            raise ValueError(f"PooledSource: planes must be (C ≤ 4, H, W) float32, got {planes.shape} {planes.dtype}")
        self.planes, self.p, self.width, self.height = planes, int(p), int(width), int(height)

    @cached_property
    def interleaved(self) -> np.ndarray:
        """``(hp, wp, 4)`` float32: the planes interleaved, padded with zeros to four channels."""
        c, h, w = self.planes.shape
        out = np.zeros((h, w, 4), np.float32)
        out[..., :c] = self.planes.transpose(1, 2, 0)
        return out


@lru_cache(maxsize=8)
def _base_grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    """``(j, i)`` float64 ``(ny, nx)``: every view pixel's column and row (read only)."""
    j, i = np.meshgrid(np.arange(nx, dtype=np.float64), np.arange(ny, dtype=np.float64))
    j.setflags(write=False)
    i.setflags(write=False)
    return j, i


def _corners(h: np.ndarray, nx: int, ny: int) -> np.ndarray | None:
    """``(2, 4)`` source coordinates of the grid's corner samples, None when some sample has ``w ≤`` :data:`W_MIN`
    (``w`` is affine over the grid: its minimum is at a corner)."""
    c = h @ np.array([[0.0, nx - 1.0, 0.0, nx - 1.0], [0.0, 0.0, ny - 1.0, ny - 1.0], [1.0, 1.0, 1.0, 1.0]])
    if not bool((c[2] > W_MIN).all()):
        return None
    return c[:2] / c[2]


def _reflected_range(lo: float, hi: float, n: int) -> tuple[float, float]:
    """The range of :func:`reflect101_np` over ``[lo, hi]`` (it is piecewise linear, kinked at multiples of
    ``n − 1``)."""
    m = float(max(n - 1, 1))
    if hi - lo >= 2.0 * m:
        return 0.0, m
    pts = [lo, hi, *(k * m for k in range(math.ceil(lo / m), math.floor(hi / m) + 1))]
    r = [float(reflect101_np(x, n)) for x in pts]
    return min(r), max(r)


def _map(h: np.ndarray, row: int, nx: int, ny: int, n: int, lo: float, hi: float, p: int, offset: float,
         w: np.ndarray | None) -> np.ndarray:
    """One float32 map: pooled coordinate (minus ``offset``) of each view pixel's sample along the source axis of
    ``h``'s row ``row`` (extent ``n``, pre-reflection range ``[lo, hi]``), reflected."""
    j, i = _base_grid(nx, ny)
    a = cv2.addWeighted(j, h[row, 0], i, h[row, 1], h[row, 2])
    if w is not None:
        a = cv2.divide(a, w)
    m = float(n - 1)
    if n < 2:
        a[...] = 0.0
    elif lo < -2.0 * m or hi > 2.0 * m:
        a = reflect101_np(a, n)
    else:  # m − |m − |u||: the reflection of [−2m, 2m] into [0, m]
        cv2.absdiff(a, 0.0, dst=a)
        cv2.absdiff(a, m, dst=a)
        a = cv2.addWeighted(a, -1.0 / p, a, 0.0, (m + 0.5) / p - 0.5 - offset, dtype=cv2.CV_32F)
        return a
    return ((a + 0.5) / p - 0.5 - offset).astype(np.float32)


def _maps(src: PooledSource, h: np.ndarray, nx: int, ny: int, corners: np.ndarray):
    """Reflected float32 maps of a view into the pooled source, relative to the region they read:
    ``(map_x, map_y, (x_lo, y_lo, x_hi, y_hi))``."""
    w = None
    if h[2, 0] != 0.0 or h[2, 1] != 0.0 or h[2, 2] != 1.0:
        j, i = _base_grid(nx, ny)
        w = cv2.addWeighted(j, h[2, 0], i, h[2, 1], h[2, 2])
    hp, wp = src.planes.shape[-2:]
    out, roi = [], []
    for row, n, size in ((0, src.width, wp), (1, src.height, hp)):
        lo, hi = float(corners[row].min()), float(corners[row].max())
        r_lo, r_hi = _reflected_range(lo, hi, n)
        first = max(0, math.floor((r_lo + 0.5) / src.p - 0.5))
        last = min(size - 1, math.floor((r_hi + 0.5) / src.p - 0.5) + 1)
        out.append(_map(h, row, nx, ny, n, lo, hi, src.p, float(first), w))
        roi.append((first, last))
    (x_lo, x_hi), (y_lo, y_hi) = roi
    return out[0], out[1], (x_lo, y_lo, x_hi, y_hi)


def warp_view(src: PooledSource, h: np.ndarray, out: np.ndarray, scratch: np.ndarray) -> bool:
    """Sample one view of every plane of ``src`` into ``out``.

    Args:
        src: the pooled source.
        h: ``(3, 3)`` float64 view pixel → **source** OpenCV pixel (``H_θ · Q``, before pooling and reflection).
        out: ``(C, ny, nx)`` float32, written in place (C-contiguous planes).
        scratch: ``(ny, nx, 4)`` float32 C-contiguous work space.

    Returns:
        False when some sample lies behind the camera (nothing written: the caller takes the torch path).
    """
    ny, nx = out.shape[-2:]
    corners = _corners(h, nx, ny)
    if corners is None:
        return False
    if corners.min() >= 0.0 and corners[0].max() <= src.width - 1.0 and corners[1].max() <= src.height - 1.0:
        m = pool_matrix(src.p) @ h
        if m[2, 0] == 0.0 and m[2, 1] == 0.0 and m[2, 2] == 1.0:
            cv2.warpAffine(src.interleaved, m[:2], (nx, ny), dst=scratch, flags=_LINEAR_INVERSE,
                           borderMode=cv2.BORDER_REPLICATE)
        else:
            cv2.warpPerspective(src.interleaved, m, (nx, ny), dst=scratch, flags=_LINEAR_INVERSE,
                                borderMode=cv2.BORDER_REPLICATE)
    else:
        mx, my, (x_lo, y_lo, x_hi, y_hi) = _maps(src, h, nx, ny, corners)
        cv2.remap(src.interleaved[y_lo:y_hi + 1, x_lo:x_hi + 1], mx, my, cv2.INTER_LINEAR, dst=scratch,
                  borderMode=cv2.BORDER_REPLICATE)
    c = out.shape[0]
    cv2.mixChannels([scratch], list(out), [k for ch in range(c) for k in (ch, ch)])
    return True
