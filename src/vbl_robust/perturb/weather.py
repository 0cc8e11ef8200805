"""Weather and sensor: uniform haze (airlight blend) and additive Gaussian noise of a fixed seeded pattern.

Convention
----------
* **Haze** ``h ∈ [0, 1]`` (the fraction of airlight; Koschmieder: ``h = 1 − exp(−β d)``, extinction ``β``,
  distance ``d``): every pixel is blended with the airlight ``A``::

      x' = (1 − h) · x + h · A,      A = HAZE_AIRLIGHT = 0.8 (all channels: neutral, below saturation)

  Uniform — one ``h`` for the whole frame (the runway and its surroundings lie at similar distances on final
  approach). ``A = 0.8`` is a bright overcast-fog radiance that stays below sensor saturation, so haze lowers
  contrast without also acting as over-exposure (that is ``brightness``). Values stay in ``[0, 1]``: no clamp.
  Haze is pointwise and commutes exactly with the (normalised) blur kernels, so applying it after the optics
  (see :mod:`.compose`) equals applying it to the scene.
* **Noise** ``s ≥ 0`` (standard deviation, fraction of full scale)::

      x' = clamp(x + s · n, 0, 1)

  where ``n`` is a **fixed** standard-normal pattern, independent per pixel and channel, drawn once from
  ``numpy.random.default_rng(NOISE_SEED)`` on the grid of the sample's image (``W₀ × H₀``, the sensor) and, for a
  source resized to the detector's resolution, resized to it by area averaging (what resizing a noisy frame does
  to its noise). Fixed, so ``L(θ)`` is deterministic and continuous in ``s``; the same pattern for every image of a
  size (a sensor's noise realisation). Added last, on the perturbed frame's pixel grid (the sensor's).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import torch
from torch import nn

from .family import Family, Pointwise

__all__ = [
    "HAZE",
    "HAZE_AIRLIGHT",
    "SENSOR_NOISE",
    "NOISE_SEED",
    "GaussianNoise",
    "Haze",
    "gaussian_noise",
    "gaussian_noise_numpy",
    "haze",
    "haze_numpy",
    "noise_pattern",
    "noise_pattern_tensor",
]

#: Airlight ``A`` of :func:`haze` (all channels), fraction of full scale.
HAZE_AIRLIGHT = 0.8
#: Seed of the fixed noise pattern of :func:`noise_pattern`.
NOISE_SEED = 0


def haze(images: torch.Tensor, amount) -> torch.Tensor:
    """Blend images with the airlight: ``(1 − h) x + h A`` (module *Convention*).

    Args:
        images: ``(B, C, …)`` or ``(1, C, …)`` (broadcast over the rows) floating point in ``[0, 1]``.
        amount: ``(B,)`` haze fractions ``h ∈ [0, 1]``.

    Returns:
        like ``images`` (batch ``B``); differentiable w.r.t. ``h`` and ``images``.

    >>> haze(torch.tensor([[[0.2]]]), torch.tensor([0.5])).flatten().tolist()
    [0.5]
    """
    if images.ndim < 2 or not images.is_floating_point():
        raise ValueError(f"haze: images must be floating point (B, C, ...), got {tuple(images.shape)} {images.dtype}")
    h = torch.as_tensor(amount, device=images.device).to(images.dtype).reshape(-1, *([1] * (images.ndim - 1)))
    if images.shape[0] not in (1, h.shape[0]):
        raise ValueError(f"haze: {images.shape[0]} images for {h.shape[0]} rows (give 1 image or one per row)")
    return torch.lerp(images, torch.full_like(images[:1], HAZE_AIRLIGHT), h)


def haze_(values: torch.Tensor, amount) -> torch.Tensor:
    """:func:`haze` in place on ``values`` ``(B, C, …)`` (no gradient; the same values)."""
    h = torch.as_tensor(amount, device=values.device).to(values.dtype).reshape(-1, *([1] * (values.ndim - 1)))
    return values.lerp_(values.new_full((1,) * values.ndim, HAZE_AIRLIGHT), h)


def haze_numpy(image: np.ndarray, amount: float, out: np.ndarray | None = None) -> np.ndarray:
    """NumPy twin of :func:`haze` for one float image ``(H, W, C)``; ``out`` may be ``image`` itself."""
    h = float(amount)
    out = np.multiply(image, 1.0 - h, out=out, dtype=image.dtype)
    out += np.asarray(h * HAZE_AIRLIGHT, dtype=out.dtype)
    return out


@lru_cache(maxsize=4)
def _pattern(height: int, width: int, channels: int, base_w: int, base_h: int, seed: int) -> np.ndarray:
    from .resample import resize_image

    rng = np.random.default_rng(seed)
    base = rng.standard_normal((base_h, base_w, 3), dtype=np.float32)[..., :channels]
    out = np.ascontiguousarray(resize_image(np.ascontiguousarray(base), (width, height)), dtype=np.float32)
    out = out.reshape(height, width, channels)
    out.setflags(write=False)
    return out


def noise_pattern(height: int, width: int, channels: int = 3, *, base_size: tuple[int, int] | None = None,
                  seed: int = NOISE_SEED) -> np.ndarray:
    """The fixed noise pattern ``(height, width, channels)`` float32 (read-only, cached).

    Args:
        height, width: the grid the noise is added on (the source the perturbation is applied to).
        channels: 1 or 3.
        base_size: ``(W₀, H₀)`` of the sample's image when the source is a resized copy (the pattern is drawn
            there and area-resized); ``None`` = the grid itself.
        seed: the generator's seed (:data:`NOISE_SEED`).
    """
    bw, bh = (int(width), int(height)) if base_size is None else (int(base_size[0]), int(base_size[1]))
    if channels not in (1, 3):
        raise ValueError(f"noise_pattern: channels must be 1 or 3, got {channels}")
    return _pattern(int(height), int(width), int(channels), bw, bh, int(seed))


@lru_cache(maxsize=4)
def _pattern_tensor(height: int, width: int, channels: int, base_w: int, base_h: int, seed: int) -> torch.Tensor:
    return torch.from_numpy(np.array(_pattern(height, width, channels, base_w, base_h, seed))).permute(2, 0, 1)


def noise_pattern_tensor(height: int, width: int, channels: int = 3, *, base_size: tuple[int, int] | None = None,
                         seed: int = NOISE_SEED) -> torch.Tensor:
    """:func:`noise_pattern` channels first, ``(channels, height, width)`` float32 (cached: do not write to it)."""
    noise_pattern(height, width, channels, base_size=base_size, seed=seed)  # validates
    bw, bh = (int(width), int(height)) if base_size is None else (int(base_size[0]), int(base_size[1]))
    return _pattern_tensor(int(height), int(width), int(channels), bw, bh, int(seed))


def gaussian_noise(images: torch.Tensor, std, pattern: torch.Tensor) -> torch.Tensor:
    """Add the fixed pattern scaled by ``std`` and clamp to ``[0, 1]`` (module *Convention*).

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the rows) floating point in ``[0, 1]``.
        std: ``(B,)`` standard deviations, fraction of full scale (≥ 0).
        pattern: ``(C, H, W)`` the fixed standard-normal pattern (:func:`noise_pattern`, channels first).

    Returns:
        ``(B, C, H, W)`` in ``[0, 1]``; differentiable w.r.t. ``std`` and ``images`` (zero where clamped).
    """
    if images.ndim != 4 or not images.is_floating_point():
        raise ValueError(f"gaussian_noise: images must be floating point (B, C, H, W), got {tuple(images.shape)}")
    s = torch.as_tensor(std, device=images.device).to(images.dtype).reshape(-1, 1, 1, 1)
    if images.shape[0] not in (1, s.shape[0]):
        raise ValueError(f"gaussian_noise: {images.shape[0]} images for {s.shape[0]} rows")
    p = torch.as_tensor(pattern, device=images.device).to(images.dtype)
    if p.shape != images.shape[1:]:
        raise ValueError(f"gaussian_noise: pattern {tuple(p.shape)} does not match images {tuple(images.shape[1:])}")
    return (images + s * p[None]).clamp(0.0, 1.0)


def gaussian_noise_numpy(image: np.ndarray, std: float, pattern: np.ndarray,
                         out: np.ndarray | None = None) -> np.ndarray:
    """NumPy twin of :func:`gaussian_noise` for one float image ``(H, W, C)`` and a pattern ``(H, W, C)``."""
    if pattern.shape != image.shape:
        raise ValueError(f"gaussian_noise_numpy: pattern {pattern.shape} does not match image {image.shape}")
    noise = np.multiply(pattern, np.asarray(std, dtype=image.dtype), dtype=image.dtype)
    out = np.add(image, noise, out=out, dtype=image.dtype)
    return np.clip(out, 0.0, 1.0, out=out)


class Haze(nn.Module):
    """Module form of :func:`haze`: ``Haze()(images, amount)``."""

    def forward(self, images: torch.Tensor, amount) -> torch.Tensor:
        return haze(images, amount)


class GaussianNoise(nn.Module):
    """Module form of :func:`gaussian_noise` with the pattern of :func:`noise_pattern` for the images' size."""

    def __init__(self, seed: int = NOISE_SEED):
        super().__init__()
        self.seed = int(seed)

    def forward(self, images: torch.Tensor, std) -> torch.Tensor:
        c, h, w = images.shape[-3:]
        return gaussian_noise(images, std, noise_pattern_tensor(h, w, c, seed=self.seed))


class _Haze(Pointwise):
    """The registry's map of ``haze``; the blend is linear, so the frame's grey mean after it is known exactly."""

    def __init__(self):
        super().__init__("haze", haze, haze_numpy, haze_)

    def stats_after(self, stats, v, channels):
        from .photometric import LUMA_WEIGHTS

        grey = HAZE_AIRLIGHT * (sum(LUMA_WEIGHTS) if channels == 3 else 1.0)
        a = v["haze"].to(stats.dtype)
        return (1.0 - a) * stats + a * grey


class _SensorNoise(Family):
    """The registry's map of ``noise_std``: the fixed seeded pattern on the sample's pixel grid (a fresh draw from
    ``ctx.rng`` in training)."""

    params = ("noise_std",)

    def frame_numpy(self, frame, v, ctx, out):
        h, w, c = frame.shape
        pattern = noise_pattern(h, w, c, base_size=ctx.scale.original_size(w, h))
        return gaussian_noise_numpy(frame, v["noise_std"], pattern, out=out)

    def frame_torch(self, x, v, ctx):
        c, h, w = x.shape[1:]
        if ctx.rng is not None:
            pattern = torch.from_numpy(ctx.rng.standard_normal((c, h, w)).astype(np.float32)).to(x.device, x.dtype)
        else:
            pattern = noise_pattern_tensor(h, w, c, base_size=ctx.scale.original_size(w, h)).to(x.device)
        return gaussian_noise(x, v["noise_std"], pattern)


#: the haze family (registry entry ``haze``)
HAZE = _Haze()
#: the sensor noise family (registry entry ``noise_std``)
SENSOR_NOISE = _SensorNoise()
