"""Optical blur: Gaussian (defocus, atmospheric turbulence) and linear horizontal motion blur.

Both are convolutions of the perturbed frame with a normalised kernel, so they preserve constants and move no
point (their point transform is the identity: the kernels are centred).

Convention
----------
* Lengths are in pixels of the image filtered (the composer converts the sample's pixels to a resized source,
  see :class:`~vbl_robust.perturb.compose.Perturbation`).
* **Gaussian blur**, ``σ ≥ 0`` px: the separable kernel ``w_k ∝ max(0, exp(−k²/2σ²) − exp(−T²/2))`` for integer
  ``k``, ``T`` = :data:`TRUNCATE` = 4 (OpenCV's float kernels also reach 4σ). Subtracting the value at ``4σ`` makes
  the kernel — and the image — *continuous* in σ (a tap enters with weight 0 when ``4σ`` passes an integer)
  while the kernel size grows with σ; it departs from ``cv2.GaussianBlur`` by at most ``e^{-8}`` ≈ 3.4e-4 of the
  peak weight per tap (images agree within 1e-3 of full scale, 3e-4 for σ ≥ 1; tested). ``σ ≤ 1/4`` is the identity (the first
  side tap would weigh less than ``e^{-8}``). Hand-written because kornia's and OpenCV's kernels jump when their
  odd size changes with σ, which would make ``L(θ)`` discontinuous.
* **Motion blur**, length ``L ≥ 0`` px along the image's **horizontal** axis (camera yaw rate × exposure): the
  average of the frame over the segment ``[u − L/2, u + L/2]``, centred on the mid-exposure position. Tap ``k``
  weighs the overlap of pixel ``[k − ½, k + ½]`` with the segment, divided by ``L`` (``L ≤ 1`` is the identity).
  Continuous and piecewise linear in ``L``; hand-written because kornia's ``motion_blur`` takes an integer size.
* **Border**: reflection without repeating the border pixel (``BORDER_REFLECT_101``, kornia's ``"reflect"``), as
  the geometric families pad.

:func:`gaussian_blur` / :func:`motion_blur` (torch, kornia ``filter2d``, differentiable w.r.t. the length) and
:func:`gaussian_blur_numpy` / :func:`motion_blur_numpy` (``cv2.sepFilter2D`` / ``cv2.filter2D``) use the same
kernels. Rows with the same kernel size are filtered together, so each row's result depends on its own
parameter only (never on the other rows of a batch).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from kornia.filters import filter2d, filter2d_separable
from torch import nn

from .family import Family

__all__ = [
    "GAUSSIAN_BLUR",
    "MOTION_BLUR",
    "TRUNCATE",
    "GaussianBlur",
    "MotionBlur",
    "gaussian_blur",
    "gaussian_blur_numpy",
    "gaussian_kernel1d",
    "gaussian_radius",
    "motion_blur",
    "motion_blur_numpy",
    "motion_kernel1d",
    "motion_radius",
]

#: The Gaussian kernel reaches ``TRUNCATE · σ`` on each side (where it is tapered to zero).
TRUNCATE = 4.0
#: A σ below this is computed as this (the kernel is the identity there anyway; avoids 0/0 in the gradient).
_SIGMA_FLOOR = 1e-3


def gaussian_radius(sigma: float) -> int:
    """Number of taps on each side of the centre with a positive weight for ``σ`` pixels."""
    t = TRUNCATE * max(float(sigma), 0.0)
    r = math.ceil(t) - 1 if t > 0 else 0  # taps with |k| < 4σ
    return max(r, 0)


def motion_radius(length: float) -> int:
    """Number of taps on each side of the centre with a positive weight for a motion of ``length`` pixels."""
    length = max(float(length), 1.0)
    return max(math.ceil((length + 1.0) / 2.0) - 1, 0)


def gaussian_kernel1d(sigma, radius: int):
    """Tapered Gaussian kernels ``(B, 2·radius + 1)`` for ``σ`` ``(B,)`` pixels (module *Convention*), each summing
    to 1; NumPy in → NumPy out, a tensor → a tensor differentiable w.r.t. σ. ``radius`` may exceed
    :func:`gaussian_radius` (the extra taps are exactly 0)."""
    if isinstance(sigma, torch.Tensor):
        s = sigma.reshape(-1, 1).clamp_min(_SIGMA_FLOOR)
        k = torch.arange(-radius, radius + 1, dtype=s.dtype, device=s.device)[None, :]
        w = (torch.exp(-0.5 * (k / s) ** 2) - math.exp(-0.5 * TRUNCATE**2)).clamp_min(0.0)
        return w / w.sum(dim=1, keepdim=True)
    s = np.maximum(np.asarray(sigma, dtype=np.float64).reshape(-1, 1), _SIGMA_FLOOR)
    k = np.arange(-radius, radius + 1, dtype=np.float64)[None, :]
    w = np.maximum(np.exp(-0.5 * (k / s) ** 2) - math.exp(-0.5 * TRUNCATE**2), 0.0)
    return w / w.sum(axis=1, keepdims=True)


def motion_kernel1d(length, radius: int):
    """Box kernels ``(B, 2·radius + 1)`` of a centred motion of ``length`` ``(B,)`` pixels (module *Convention*),
    each summing to 1; NumPy or torch (differentiable w.r.t. the length)."""
    if isinstance(length, torch.Tensor):
        half = 0.5 * length.reshape(-1, 1).clamp_min(1.0)
        k = torch.arange(-radius, radius + 1, dtype=half.dtype, device=half.device)[None, :]
        w = (torch.minimum(k + 0.5, half) - torch.maximum(k - 0.5, -half)).clamp_min(0.0)
        return w / (2.0 * half)
    half = 0.5 * np.maximum(np.asarray(length, dtype=np.float64).reshape(-1, 1), 1.0)
    k = np.arange(-radius, radius + 1, dtype=np.float64)[None, :]
    w = np.maximum(np.minimum(k + 0.5, half) - np.maximum(k - 0.5, -half), 0.0)
    return w / (2.0 * half)


def _check(images: torch.Tensor, what: str) -> None:
    if images.ndim != 4:
        raise ValueError(f"{what}: images must have shape (B, C, H, W), got {tuple(images.shape)}")
    if not images.is_floating_point():
        raise ValueError(f"{what}: images must be floating point, got {images.dtype}")


def _rows(values: torch.Tensor, images: torch.Tensor, what: str) -> tuple[torch.Tensor, torch.Tensor]:
    b = values.shape[0]
    if images.shape[0] not in (1, b):
        raise ValueError(f"{what}: {images.shape[0]} images for {b} parameter rows (give 1 image or one per row)")
    return values, (images.expand(b, -1, -1, -1) if images.shape[0] == 1 and b > 1 else images)


def _group_by_radius(radii: list[int]):
    for r in sorted(set(radii)):
        yield r, [i for i, ri in enumerate(radii) if ri == r]


def gaussian_blur(images: torch.Tensor, sigma_px) -> torch.Tensor:
    """Blur images with a Gaussian of ``σ`` pixels (module *Convention*: tapered at 4σ, reflect-101 border).

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the rows) floating point.
        sigma_px: ``(B,)`` standard deviations in pixels of ``images`` (≥ 0), or ``(B, 2)`` for ``(σ_x, σ_y)``.

    Returns:
        ``(B, C, H, W)`` like ``images``; differentiable w.r.t. σ and ``images``.

    >>> x = torch.zeros(1, 1, 1, 9, dtype=torch.float64); x[..., 4] = 1.0
    >>> y = gaussian_blur(x, torch.tensor([[1.0, 0.0]], dtype=torch.float64))
    >>> round(float(y.sum()), 12), round(float(y[0, 0, 0, 3] / y[0, 0, 0, 4]), 4)   # mass kept; exp(−½), tapered
    (1.0, 0.6064)
    """
    _check(images, "gaussian_blur")
    s = torch.as_tensor(sigma_px, device=images.device)
    s = s.to(images.dtype) if s.is_floating_point() else s.to(images.dtype)
    s = s.reshape(-1, 1).expand(-1, 2) if s.ndim <= 1 else s
    if s.ndim != 2 or s.shape[1] != 2:
        raise ValueError(f"gaussian_blur: sigma_px must be (B,) or (B, 2), got {tuple(s.shape)}")
    s, x = _rows(s, images, "gaussian_blur")
    h, w = x.shape[-2:]
    rx = [min(gaussian_radius(v), w - 1) for v in s[:, 0].detach().cpu().tolist()]
    ry = [min(gaussian_radius(v), h - 1) for v in s[:, 1].detach().cpu().tolist()]
    pairs = list(zip(rx, ry, strict=True))
    if all(p == (0, 0) for p in pairs):
        return x + 0.0 * s.sum()  # the identity for every row (keeps the graph)
    out = torch.empty_like(x)
    for pair in sorted(set(pairs)):
        idx = [i for i, p in enumerate(pairs) if p == pair]
        sub = x[idx]
        kx = gaussian_kernel1d(s[idx, 0], pair[0])
        ky = gaussian_kernel1d(s[idx, 1], pair[1])
        if pair == (0, 0):
            out[idx] = sub * kx[:, :1, None, None] * ky[:, :1, None, None]
        else:
            out[idx] = filter2d_separable(sub, kx, ky, border_type="reflect")
    return out


def motion_blur(images: torch.Tensor, length_px) -> torch.Tensor:
    """Blur images by a centred linear motion of ``length_px`` pixels along the horizontal axis.

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the rows) floating point.
        length_px: ``(B,)`` lengths in pixels of ``images`` (≥ 0).

    Returns:
        ``(B, C, H, W)`` like ``images``; differentiable w.r.t. the length and ``images``.

    >>> x = torch.zeros(1, 1, 1, 9, dtype=torch.float64); x[..., 4] = 1.0
    >>> motion_blur(x, torch.tensor([3.0], dtype=torch.float64))[0, 0, 0, 2:7].tolist() == [0, 1/3, 1/3, 1/3, 0]
    True
    """
    _check(images, "motion_blur")
    n = torch.as_tensor(length_px, device=images.device).to(images.dtype).reshape(-1)
    n, x = _rows(n, images, "motion_blur")
    w = x.shape[-1]
    radii = [min(motion_radius(v), w - 1) for v in n.detach().cpu().tolist()]
    if all(r == 0 for r in radii):
        return x + 0.0 * n.sum()
    out = torch.empty_like(x)
    for r, idx in _group_by_radius(radii):
        k = motion_kernel1d(n[idx], r)
        out[idx] = x[idx] * k[:, :1, None, None] if r == 0 else filter2d(x[idx], k[:, None, :], border_type="reflect")
    return out


def gaussian_blur_numpy(image: np.ndarray, sigma_x: float, sigma_y: float | None = None,
                        out: np.ndarray | None = None) -> np.ndarray:
    """OpenCV twin of :func:`gaussian_blur` for one image ``(H, W, C)`` (``cv2.sepFilter2D``, same kernel,
    ``BORDER_REFLECT_101``); ``sigma_y`` defaults to ``sigma_x``. No gradient. ``out`` may be ``image`` itself."""
    import cv2

    sigma_y = sigma_x if sigma_y is None else sigma_y
    for name, v in (("sigma_x", sigma_x), ("sigma_y", sigma_y)):
        if not (math.isfinite(float(v)) and float(v) >= 0.0):
            raise ValueError(f"gaussian_blur_numpy: {name} must be finite and >= 0, got {v}")
    h, w = image.shape[:2]
    rx, ry = min(gaussian_radius(sigma_x), w - 1), min(gaussian_radius(sigma_y), h - 1)
    kx = gaussian_kernel1d(np.array([sigma_x]), rx)[0]
    ky = gaussian_kernel1d(np.array([sigma_y]), ry)[0]
    res = cv2.sepFilter2D(image, -1, kx, ky, dst=out, borderType=cv2.BORDER_REFLECT_101)
    return res.reshape(image.shape)


def motion_blur_numpy(image: np.ndarray, length_px: float, out: np.ndarray | None = None) -> np.ndarray:
    """OpenCV twin of :func:`motion_blur` for one image ``(H, W, C)`` (``cv2.filter2D``, same kernel,
    ``BORDER_REFLECT_101``). No gradient. ``out`` may be ``image`` itself."""
    import cv2

    if not (math.isfinite(float(length_px)) and float(length_px) >= 0.0):
        raise ValueError(f"motion_blur_numpy: length_px must be finite and >= 0, got {length_px}")
    r = min(motion_radius(length_px), image.shape[1] - 1)
    k = motion_kernel1d(np.array([length_px]), r)
    res = cv2.filter2D(image, -1, k, dst=out, borderType=cv2.BORDER_REFLECT_101)
    return res.reshape(image.shape)


class GaussianBlur(nn.Module):
    """Module form of :func:`gaussian_blur`: ``GaussianBlur()(images, sigma_px)``."""

    def forward(self, images: torch.Tensor, sigma_px) -> torch.Tensor:
        return gaussian_blur(images, sigma_px)


class MotionBlur(nn.Module):
    """Module form of :func:`motion_blur`: ``MotionBlur()(images, length_px)``."""

    def forward(self, images: torch.Tensor, length_px) -> torch.Tensor:
        return motion_blur(images, length_px)


class _GaussianBlur(Family):
    """The registry's map of ``blur_px`` (σ in the sample's pixels, scaled to the frame's)."""

    params = ("blur_px",)

    def frame_numpy(self, frame, v, ctx, out):
        s = v["blur_px"]
        return gaussian_blur_numpy(frame, s * ctx.scale.sx, s * ctx.scale.sy, out=out)

    def frame_torch(self, x, v, ctx):
        s = v["blur_px"]
        return gaussian_blur(x, torch.stack([s * ctx.scale.sx, s * ctx.scale.sy], dim=-1))


class _MotionBlur(Family):
    """The registry's map of ``motion_blur_px`` (horizontal length in the sample's pixels, scaled to the frame's)."""

    params = ("motion_blur_px",)

    def frame_numpy(self, frame, v, ctx, out):
        return motion_blur_numpy(frame, v["motion_blur_px"] * ctx.scale.sx, out=out)

    def frame_torch(self, x, v, ctx):
        return motion_blur(x, v["motion_blur_px"] * ctx.scale.sx)


#: the Gaussian blur family (registry entry ``blur_px``)
GAUSSIAN_BLUR = _GaussianBlur()
#: the motion blur family (registry entry ``motion_blur_px``)
MOTION_BLUR = _MotionBlur()
