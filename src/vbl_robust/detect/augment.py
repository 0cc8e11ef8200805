"""Appearance jitter of training images: blur, haze, contrast, brightness, gamma and sensor noise.

Why: the families ranking (``reproduce families``, 30 images, session 8) puts sensor noise first by far
(σ = 0.05 of full scale already breaks a third of the images that survive unperturbed), then brightness, motion
blur, haze and blur; the training data had none of them (ultralytics' HSV jitter only). Issue 14 asks for
"lighting, haze and sensor-noise variation" in the training data.

What: with probability ``p`` a training sample's *source image* (full resolution, before any view is cut) gets
a random appearance change; each family is then drawn independently with probability ``p_family``, its value
uniform in its range (log-uniform for the registry's multiplicative families, contrast and gamma), and applied in
the registry's order (optics, then photometry, then noise: :mod:`vbl_robust.perturb.registry`). The maps are the
families' own (:meth:`Family.frame_torch <vbl_robust.perturb.family.Family.frame_torch>`), so training sees
exactly what an audit applies; only the noise differs — a fresh standard-normal draw per sample from the sample's seed stream, not
the audit's one fixed pattern (the network must not learn one pattern). Geometry is never touched, so the
keypoint labels stay exact. Validation views are never jittered (they measure the nominal model).

The ranges are moderate (about the registry's level 2–3): the aim is a detector that is not needlessly fragile,
not one trained on the audit's extreme levels.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from ..perturb.family import FrameContext
from ..perturb.registry import PERTURBATIONS, family_of
from ..perturb.resample import PixelScale

__all__ = ["AppearanceJitter"]


@dataclass(frozen=True)
class AppearanceJitter:
    """Random appearance changes of a training image (module docstring).

    Args:
        p: probability that a sample is changed at all.
        p_family: probability of each family, given that the sample is changed.
        blur_px, motion_blur_px: Gaussian σ / motion length ranges in source pixels.
        haze: airlight fraction range; contrast, gamma: factor ranges (log-uniform); brightness: offset range
            (fraction of full scale); noise_std: standard deviation range (fraction of full scale).
    """

    p: float = 0.5
    p_family: float = 0.35
    blur_px: tuple[float, float] = (0.0, 1.5)
    motion_blur_px: tuple[float, float] = (0.0, 4.0)
    haze: tuple[float, float] = (0.0, 0.3)
    contrast: tuple[float, float] = (0.7, 1.4)
    brightness: tuple[float, float] = (-0.15, 0.15)
    gamma: tuple[float, float] = (0.75, 1.33)
    noise_std: tuple[float, float] = (0.0, 0.05)

    @classmethod
    def families(cls) -> tuple[str, ...]:
        """The jittered families (the range fields), in the registry's order."""
        fields = cls.__dataclass_fields__
        return tuple(n for n in PERTURBATIONS if n in fields)

    def __post_init__(self) -> None:
        for name in ("p", "p_family"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0.0 <= v <= 1.0):
                raise ValueError(f"AppearanceJitter: {name} must be in [0, 1], got {v!r}")
        for name in self.families():
            spec, log = PERTURBATIONS[name], PERTURBATIONS[name].multiplicative
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi) or (log and lo <= 0):
                raise ValueError(f"AppearanceJitter: {name} must be a finite (low, high) range"
                                 f"{' of positive factors' if log else ''}, got {(lo, hi)!r}")
            if lo < spec.minimum or hi > spec.maximum:
                raise ValueError(f"AppearanceJitter: {name} must lie within [{spec.minimum:g}, {spec.maximum:g}], "
                                 f"got {(lo, hi)!r}")

    def to_dict(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        """The changes of one sample: ``{family: value}`` (empty: unchanged). Consumes ``rng`` the same way
        whatever is drawn, so the rest of a sample's stream does not depend on it."""
        names = self.families()
        u = rng.random(1 + 2 * len(names))
        if u[0] >= self.p:
            return {}
        out = {}
        for k, name in enumerate(names):
            log = PERTURBATIONS[name].multiplicative
            if u[1 + 2 * k] >= self.p_family:
                continue
            lo, hi = getattr(self, name)
            t = u[2 + 2 * k]
            out[name] = float(math.exp(math.log(lo) + t * (math.log(hi) - math.log(lo))) if log else lo + t * (hi - lo))
        return out

    def apply(self, image: torch.Tensor, rng: np.random.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        """``image`` ``(1, 3, H, W)`` float in [0, 1] with one sample's changes; returns it and the changes."""
        changes = self.draw(rng)
        if not changes:
            return image, changes
        x = image
        one = torch.ones(1, dtype=x.dtype)
        ctx = FrameContext(scale=PixelScale(), rng=rng)  # the source's own pixels; a fresh noise draw
        for name in self.families():
            if name in changes:
                x = family_of(name).frame_torch(x, {name: changes[name] * one}, ctx)
        return x.clamp(0.0, 1.0), changes
