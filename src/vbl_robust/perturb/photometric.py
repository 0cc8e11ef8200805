"""Photometric families: contrast, brightness and gamma — pointwise maps of pixel values in ``[0, 1]``.

Convention
----------
**Contrast** (torchvision's definition of a contrast factor): blend each image with the mean of its grayscale.
For an RGB image ``x`` with values in ``[0, 1]`` and a factor ``α ≥ 0``::

    m  = mean over all pixels of (0.2989 R + 0.587 G + 0.114 B)      # ITU-R 601-2 luma, per image
    x' = clamp(α · x + (1 − α) · m, 0, 1)

``α = 1`` is the identity, ``α = 0`` a uniform grey image, ``α > 1`` more contrast. Identical to
``torchvision.transforms.functional.adjust_contrast`` on float images (tested). Single-channel images use the
channel mean.

**Brightness** ``b`` (an additive offset, fraction of full scale: ``b = 0.1`` adds 25.5 grey levels)::

    x' = clamp(x + b, 0, 1)                                           # kornia.enhance.adjust_brightness

**Gamma** ``γ ≥ 0`` (a tone curve; ``γ < 1`` brightens the shadows, ``γ > 1`` darkens them)::

    x' = x ** γ                                                       # kornia.enhance.adjust_gamma (gain 1)

All three move no pixel: their point transform is the identity. Each is differentiable w.r.t. its parameter
(torch's ``pow`` has a finite gradient in the exponent at ``x = 0``).
"""

from __future__ import annotations

import numpy as np
import torch
from kornia.enhance import adjust_brightness, adjust_gamma
from torch import nn

from .family import Family, Pointwise

__all__ = [
    "BRIGHTNESS",
    "CONTRAST",
    "GAMMA",
    "LUMA_WEIGHTS",
    "Brightness",
    "Contrast",
    "Gamma",
    "brightness",
    "brightness_numpy",
    "contrast",
    "contrast_about",
    "contrast_numpy",
    "gamma",
    "gamma_numpy",
    "gray_mean",
]

#: ITU-R 601-2 luma weights used by torchvision's ``rgb_to_grayscale``.
LUMA_WEIGHTS = (0.2989, 0.587, 0.114)


def contrast(images: torch.Tensor, factor: torch.Tensor) -> torch.Tensor:
    """Scale the contrast of each image by ``factor`` (see module *Convention*).

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the factors), float in ``[0, 1]``, ``C`` ∈ {1, 3}.
        factor: ``(B,)`` non-negative contrast factors (dimensionless).

    Returns:
        ``(B, C, H, W)`` in ``[0, 1]``; differentiable w.r.t. ``factor`` and ``images`` (zero gradient where clamped).

    >>> x = torch.tensor([0.2, 0.4, 0.6], dtype=torch.float64).view(1, 1, 1, 3)   # one channel, mean 0.4
    >>> [round(v, 6) for v in contrast(x, torch.tensor([2.0])).flatten().tolist()]
    [0.0, 0.4, 0.8]
    """
    if images.ndim != 4 or images.shape[1] not in (1, 3):
        raise ValueError(f"contrast: images must have shape (B, 1 or 3, H, W), got {tuple(images.shape)}")
    if not images.is_floating_point():
        raise ValueError(f"contrast: images must be floating point in [0, 1], got {images.dtype}")
    f = torch.as_tensor(factor, device=images.device).to(images.dtype).reshape(-1)
    if images.shape[0] not in (1, f.shape[0]):
        raise ValueError(f"contrast: {images.shape[0]} images for {f.shape[0]} factors (give 1 image or one per factor)")
    mean = gray_mean(images)  # (B or 1,)
    f4 = f[:, None, None, None]
    return (f4 * images + (1.0 - f4) * mean[:, None, None, None]).clamp(0.0, 1.0)


def contrast_about(values: torch.Tensor, factor: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """:func:`contrast` of pixel values ``(B, C, …)`` of images whose grey means ``(B,)`` are known (the view
    sampler gives views, not whole images, so the mean comes from the whole frame)."""
    f = torch.as_tensor(factor).to(values.dtype).reshape(-1, *([1] * (values.ndim - 1)))
    m = torch.as_tensor(mean).to(values.dtype).reshape(-1, *([1] * (values.ndim - 1)))
    return (f * values + (1.0 - f) * m).clamp(0.0, 1.0)


def contrast_about_(values: torch.Tensor, factor: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """:func:`contrast_about` in place on ``values`` (no gradient; the same operations, the same values)."""
    f = torch.as_tensor(factor).to(values.dtype).reshape(-1, *([1] * (values.ndim - 1)))
    m = torch.as_tensor(mean).to(values.dtype).reshape(-1, *([1] * (values.ndim - 1)))
    return values.mul_(f).add_((1.0 - f) * m).clamp_(0.0, 1.0)


def gray_mean(images: torch.Tensor) -> torch.Tensor:
    """(B,) grayscale mean of each image (ITU-R 601 luma for RGB): the grey level contrast scales about."""
    if images.shape[1] == 3:
        w = torch.tensor(LUMA_WEIGHTS, dtype=images.dtype, device=images.device)
        return torch.einsum("bchw,c->b", images, w) / (images.shape[-1] * images.shape[-2])
    return images.mean(dim=(1, 2, 3))


def contrast_numpy(image: np.ndarray, factor: float, out: np.ndarray | None = None) -> np.ndarray:
    """NumPy/OpenCV twin of :func:`contrast` for one float image ``(H, W, C)`` in ``[0, 1]`` (C ∈ {1, 3}).

    No gradient. ``out`` (same shape, float32/float64; may be ``image`` itself) receives the result.
    """
    import cv2

    if image.ndim != 3 or image.shape[2] not in (1, 3):
        raise ValueError(f"contrast_numpy: image must have shape (H, W, 1 or 3), got {image.shape}")
    means = cv2.mean(image)  # per-channel means, accumulated in float64 (~15x faster than numpy here)
    mean = float(np.dot(means[:3], LUMA_WEIGHTS)) if image.shape[2] == 3 else float(means[0])
    f = float(factor)
    out = np.multiply(image, f, out=out, dtype=image.dtype)
    out += np.asarray((1.0 - f) * mean, dtype=out.dtype)
    return np.clip(out, 0.0, 1.0, out=out)


class Contrast(nn.Module):
    """Module form of :func:`contrast`: ``Contrast()(images, factor)``."""

    def forward(self, images: torch.Tensor, factor: torch.Tensor) -> torch.Tensor:
        return contrast(images, factor)


def _factor(values: torch.Tensor, factor, what: str) -> torch.Tensor:
    f = torch.as_tensor(factor, device=values.device).to(values.dtype).reshape(-1)
    if values.ndim < 2 or values.shape[0] not in (1, f.shape[0]):
        raise ValueError(f"{what}: {tuple(values.shape)} images for {f.shape[0]} factors (give 1 image or one per "
                         "factor, shape (B, C, ...))")
    return f


def _broadcast_rows(values: torch.Tensor, b: int) -> torch.Tensor:
    return values.expand(b, *values.shape[1:]) if values.shape[0] == 1 and b > 1 else values


def brightness(images: torch.Tensor, offset) -> torch.Tensor:
    """Add ``offset`` (fraction of full scale) to every pixel and clamp to ``[0, 1]`` (see module *Convention*).

    Args:
        images: ``(B, C, …)`` or ``(1, C, …)`` (broadcast over the offsets), float in ``[0, 1]``.
        offset: ``(B,)`` offsets (any sign).

    Returns:
        like ``images`` (batch ``B``); differentiable w.r.t. ``offset`` and ``images`` (zero gradient where clamped).

    >>> [round(v, 6) for v in brightness(torch.tensor([[[0.2, 0.95]]]), torch.tensor([0.1])).flatten().tolist()]
    [0.3, 1.0]
    """
    if not images.is_floating_point():
        raise ValueError(f"brightness: images must be floating point in [0, 1], got {images.dtype}")
    f = _factor(images, offset, "brightness")
    return adjust_brightness(_broadcast_rows(images, f.shape[0]), f)


def brightness_(values: torch.Tensor, offset) -> torch.Tensor:
    """:func:`brightness` in place on ``values`` ``(B, C, …)`` (no gradient; the same values)."""
    return values.add_(_factor(values, offset, "brightness").reshape(-1, *([1] * (values.ndim - 1)))).clamp_(0.0, 1.0)


def brightness_numpy(image: np.ndarray, offset: float, out: np.ndarray | None = None) -> np.ndarray:
    """NumPy twin of :func:`brightness` for one float image ``(H, W, C)``; ``out`` may be ``image`` itself."""
    out = np.add(image, np.asarray(offset, dtype=image.dtype), out=out, dtype=image.dtype)
    return np.clip(out, 0.0, 1.0, out=out)


def gamma(images: torch.Tensor, exponent) -> torch.Tensor:
    """Raise every pixel to the power ``γ`` (see module *Convention*).

    Args:
        images: ``(B, C, …)`` or ``(1, C, …)`` (broadcast over the exponents), float in ``[0, 1]``.
        exponent: ``(B,)`` exponents ``γ ≥ 0``.

    Returns:
        like ``images`` (batch ``B``) in ``[0, 1]``; differentiable w.r.t. ``γ`` and ``images``.

    >>> gamma(torch.tensor([[[0.25]]], dtype=torch.float64), torch.tensor([0.5])).flatten().tolist()
    [0.5]
    """
    if not images.is_floating_point():
        raise ValueError(f"gamma: images must be floating point in [0, 1], got {images.dtype}")
    f = _factor(images, exponent, "gamma")
    if bool((f < 0).any()):
        raise ValueError(f"gamma: exponents must be >= 0, got {float(f.min()):g}")
    return adjust_gamma(_broadcast_rows(images, f.shape[0]), f)


def gamma_(values: torch.Tensor, exponent) -> torch.Tensor:
    """:func:`gamma` in place on ``values`` ``(B, C, …)`` (no gradient; the same values: kornia's gain is 1)."""
    return values.pow_(_factor(values, exponent, "gamma").reshape(-1, *([1] * (values.ndim - 1)))).clamp_(0.0, 1.0)


def gamma_numpy(image: np.ndarray, exponent: float, out: np.ndarray | None = None) -> np.ndarray:
    """NumPy twin of :func:`gamma` for one float image ``(H, W, C)`` in ``[0, 1]``; ``out`` may be ``image``."""
    out = np.power(image, np.asarray(exponent, dtype=image.dtype), out=out, dtype=image.dtype)
    return np.clip(out, 0.0, 1.0, out=out)


class Brightness(nn.Module):
    """Module form of :func:`brightness`: ``Brightness()(images, offset)``."""

    def forward(self, images: torch.Tensor, offset) -> torch.Tensor:
        return brightness(images, offset)


class Gamma(nn.Module):
    """Module form of :func:`gamma`: ``Gamma()(images, exponent)``."""

    def forward(self, images: torch.Tensor, exponent) -> torch.Tensor:
        return gamma(images, exponent)


class _Contrast(Family):
    """The registry's map of ``contrast``: about the grey mean of the whole frame, or of the geometrically perturbed
    frame (``stats``) when only sampled pixel values are at hand."""

    params = ("contrast",)
    needs_stats = True

    def frame_numpy(self, frame, v, ctx, out):
        return contrast_numpy(frame, v["contrast"], out=out)

    def frame_torch(self, x, v, ctx):
        return contrast(x, v["contrast"].to(x.device))

    def pointwise(self, values, v, stats):
        return contrast_about(values, v["contrast"], stats)

    def pointwise_(self, values, v, stats):
        return contrast_about_(values, v["contrast"], stats)


#: the contrast family (registry entry ``contrast``)
CONTRAST = _Contrast()
#: the brightness family (registry entry ``brightness``)
BRIGHTNESS = Pointwise("brightness", brightness, brightness_numpy, brightness_)
#: the gamma family (registry entry ``gamma``)
GAMMA = Pointwise("gamma", gamma, gamma_numpy, gamma_)
