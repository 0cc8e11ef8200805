"""Camera roll as an image rotation about the principal point, and its 2D point transform.

Convention
----------
* Pixels as in :mod:`vbl_robust.geometry.camera` (OpenCV): ``u`` right, ``v`` down, pixel centres at integer
  coordinates. The rotation centre is the **principal point** ``(cx, cy)`` of ``K`` (LARD: ``(W/2, H/2)``), not
  the geometric image centre ``((W−1)/2, (H−1)/2)``.
* **Sign**: ``angle_deg = +φ`` is a camera roll of ``+φ`` about the optical axis in the LARD sense (right wing
  down). Rolling the camera right-wing-down makes the scene turn **counter-clockwise on screen**, so a pixel at
  ``p`` moves to::

      p' = c + [[cos φ,  sin φ],
                [−sin φ, cos φ]] (p − c)

  (a point right of the centre moves up). This is ``cv2.getRotationMatrix2D(c, φ, 1)`` and kornia's
  ``rotate(…, angle=φ)``. For a pinhole camera with square pixels and the centre at the principal point the
  mapping is *exact*: the rolled image is the image the camera would take with LARD roll ``roll + φ``
  (``R · Rx(φ)``), from the same position. Hence ideal pose estimation is roll-invariant.
* **Padding**: reflection without repeating the border pixel (OpenCV ``BORDER_REFLECT_101``, ``gfedcb|abcdefgh``),
  which is what ``grid_sample(padding_mode="reflection", align_corners=True)`` does; bilinear interpolation.

``roll`` (torch, differentiable w.r.t. the angle) and ``roll_numpy`` (OpenCV, no gradient, ~10× faster on CPU)
agree to float32 rounding (tested).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from kornia.geometry.transform import warp_affine
from torch import nn

__all__ = ["Roll", "default_center", "roll", "roll_matrix", "roll_numpy", "roll_points", "roll_source_coords"]


def default_center(width: int, height: int) -> tuple[float, float]:
    """The principal point of :func:`vbl_robust.geometry.camera.intrinsics`: ``(W/2, H/2)`` pixels."""
    return (width / 2.0, height / 2.0)


def _batch_center(center, batch: int, width: int, height: int, like: torch.Tensor) -> torch.Tensor:
    if center is None:
        center = default_center(width, height)
    c = torch.as_tensor(center, dtype=like.dtype, device=like.device)
    if c.shape == (2,):
        c = c.expand(batch, 2)
    if c.shape != (batch, 2):
        raise ValueError(f"roll: center must have shape (2,) or ({batch}, 2), got {tuple(c.shape)}")
    return c


def roll_matrix(angle_deg: torch.Tensor, center: torch.Tensor) -> torch.Tensor:
    """Affine matrices ``(B, 2, 3)`` mapping source pixels to rolled pixels (see module *Convention*).

    Args:
        angle_deg: ``(B,)`` roll angles, degrees.
        center: ``(B, 2)`` rotation centres ``(cx, cy)``, pixels.
    """
    a = torch.deg2rad(angle_deg)
    c, s = torch.cos(a), torch.sin(a)
    cx, cy = center[:, 0], center[:, 1]
    row0 = torch.stack([c, s, cx - c * cx - s * cy], dim=-1)
    row1 = torch.stack([-s, c, cy + s * cx - c * cy], dim=-1)
    return torch.stack([row0, row1], dim=-2)


def roll(images: torch.Tensor, angle_deg: torch.Tensor, center=None) -> torch.Tensor:
    """Roll the camera by ``angle_deg``: rotate images about ``center`` with reflection padding.

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the angles) floating point.
        angle_deg: ``(B,)`` degrees; ``+φ`` = right wing down = content turns counter-clockwise on screen.
        center: ``(2,)`` or ``(B, 2)`` rotation centre ``(cx, cy)`` in pixels — pass the principal point of
            ``K``; ``None`` means ``(W/2, H/2)``.

    Returns:
        ``(B, C, H, W)``, same dtype as ``images``; differentiable w.r.t. ``angle_deg`` and ``images``.

    Convention: see the module docstring (centre, sign, BORDER_REFLECT_101 padding, bilinear).

    >>> img = torch.zeros(1, 1, 5, 5); img[0, 0, 2, 4] = 1.0        # a dot right of the centre (2, 2)
    >>> out = roll(img, torch.tensor([90.0]), center=(2.0, 2.0))
    >>> [int(i) for i in torch.nonzero(out[0, 0] > 0.5)[0]]      # moved up: row 0, column 2
    [0, 2]
    """
    if images.ndim != 4:
        raise ValueError(f"roll: images must have shape (B, C, H, W), got {tuple(images.shape)}")
    if not images.is_floating_point():
        raise ValueError(f"roll: images must be floating point, got {images.dtype}")
    angle = torch.as_tensor(angle_deg, device=images.device).to(images.dtype).reshape(-1)
    b = angle.shape[0]
    if images.shape[0] not in (1, b):
        raise ValueError(f"roll: {images.shape[0]} images for {b} angles (give 1 image or one per angle)")
    h, w = images.shape[-2:]
    m = roll_matrix(angle, _batch_center(center, b, w, h, angle))
    if images.shape[0] == 1 and b > 1:
        images = images.expand(b, -1, -1, -1)
    return warp_affine(images, m, (h, w), mode="bilinear", padding_mode="reflection", align_corners=True)


def roll_points(points, angle_deg, center):
    """Move pixel points as :func:`roll` moves the image content.

    Args:
        points: ``(B, N, 2)`` or ``(N, 2)`` (broadcast over the angles) pixels ``(u, v)``; numpy or torch.
        angle_deg: ``(B,)`` degrees (same sign as :func:`roll`).
        center: ``(2,)`` or ``(B, 2)`` rotation centre, pixels.

    Returns:
        ``(B, N, 2)`` of the input's array type (torch: differentiable w.r.t. angle and points).

    >>> roll_points(np.array([[3.0, 2.0]]), np.array([90.0]), (2.0, 2.0)).round(6).tolist()
    [[[2.0, 1.0]]]
    """
    if isinstance(points, torch.Tensor) or isinstance(angle_deg, torch.Tensor):
        ref = points if isinstance(points, torch.Tensor) else angle_deg
        dtype = ref.dtype if ref.is_floating_point() else torch.float64
        p = torch.as_tensor(points, dtype=dtype, device=ref.device)
        a = torch.deg2rad(torch.as_tensor(angle_deg, device=ref.device).to(dtype).reshape(-1))
        c = torch.as_tensor(center, dtype=dtype, device=ref.device)
        xp_cos, xp_sin, stack = torch.cos, torch.sin, torch.stack
    else:
        p = np.asarray(points, dtype=np.float64)
        a = np.deg2rad(np.asarray(angle_deg, dtype=np.float64).reshape(-1))
        c = np.asarray(center, dtype=np.float64)
        xp_cos, xp_sin, stack = np.cos, np.sin, np.stack
    if p.ndim == 2:
        p = p[None]
    if p.ndim != 3 or p.shape[-1] != 2:
        raise ValueError(f"roll_points: points must have shape (B, N, 2) or (N, 2), got {tuple(p.shape)}")
    if c.shape == (2,):
        c = c[None]
    if c.ndim != 2 or c.shape[-1] != 2:
        raise ValueError(f"roll_points: center must have shape (2,) or (B, 2), got {tuple(c.shape)}")
    c = c[:, None, :]
    du, dv = p[..., 0] - c[..., 0], p[..., 1] - c[..., 1]
    co, si = xp_cos(a)[:, None], xp_sin(a)[:, None]
    return stack([c[..., 0] + co * du + si * dv, c[..., 1] - si * du + co * dv], -1)


def roll_source_coords(qu: torch.Tensor, qv: torch.Tensor, angle_deg: torch.Tensor, center: torch.Tensor,
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverse map of :func:`roll`: the source pixel shown at rolled pixel ``(qu, qv)``, i.e. ``c + Rᵀ (q − c)``.

    Args:
        qu, qv: ``(B, …)`` OpenCV coordinates in the rolled image (computed in their dtype).
        angle_deg: ``(B,)`` degrees (same sign as :func:`roll`); center: ``(2,)`` pixels.

    Returns:
        ``(su, sv)`` like ``qu``: source coordinates, not yet reflected into the image (see
        :func:`~vbl_robust.perturb.views.reflect101`). Differentiable w.r.t. the angle.
    """
    a = torch.deg2rad(torch.as_tensor(angle_deg).to(qu.dtype)).reshape(-1, *([1] * (qu.ndim - 1)))
    co, si = torch.cos(a), torch.sin(a)
    du, dv = qu - center[0], qv - center[1]
    return center[0] + co * du - si * dv, center[1] + si * du + co * dv


def roll_numpy(image: np.ndarray, angle_deg: float, center=None, out: np.ndarray | None = None) -> np.ndarray:
    """OpenCV twin of :func:`roll` for one image ``(H, W, C)`` (any dtype OpenCV warps); no gradient.

    Same convention as :func:`roll` (``cv2.warpAffine`` with ``BORDER_REFLECT_101``, bilinear). ``out``: an
    optional contiguous array of the same shape and dtype to write into (not ``image`` itself).
    """
    import cv2

    if not math.isfinite(float(angle_deg)):
        raise ValueError(f"roll_numpy: angle_deg must be finite, got {angle_deg}")
    h, w = image.shape[:2]
    cx, cy = default_center(w, h) if center is None else (float(center[0]), float(center[1]))
    m = cv2.getRotationMatrix2D((cx, cy), float(angle_deg), 1.0)
    res = cv2.warpAffine(image, m, (w, h), dst=out, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return res.reshape(image.shape)


class Roll(nn.Module):
    """Module form of :func:`roll`: ``Roll(center)(images, angle_deg)``."""

    def __init__(self, center=None):
        super().__init__()
        self.center = center

    def forward(self, images: torch.Tensor, angle_deg: torch.Tensor) -> torch.Tensor:
        return roll(images, angle_deg, self.center)
