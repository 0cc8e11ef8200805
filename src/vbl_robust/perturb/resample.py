"""Resampling an image to a detector's input resolution, and the matching pixel mapping.

Rotation about the principal point commutes with isotropic scaling, so a pipeline may resize the image once to
the detector's resolution and perturb *there* (cheaper), with the rotation centre mapped like any other point.

Convention
----------
Pixel centres at integer coordinates (OpenCV). Resizing a ``W × H`` image to ``W' × H'`` (``cv2.resize``,
``F.interpolate(align_corners=False)``) maps a point ``u`` of the original to::

    u' = s_x · (u + 0.5) − 0.5,      s_x = W' / W      (same for v with s_y = H' / H)

so pixel *edges* scale, not pixel centres. :class:`PixelScale` holds ``(s_x, s_y)`` and maps both ways.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

__all__ = ["PixelScale", "resize_image"]


@dataclass(frozen=True)
class PixelScale:
    """Mapping between original pixels and resized pixels (``s_x = W'/W``, ``s_y = H'/H``)."""

    sx: float = 1.0
    sy: float = 1.0

    @property
    def is_identity(self) -> bool:
        return self.sx == 1.0 and self.sy == 1.0

    @classmethod
    def for_long_side(cls, width: int, height: int, long_side: int | None) -> tuple[PixelScale, tuple[int, int]]:
        """Scale that brings the longer side of a ``width × height`` image to ``long_side`` pixels.

        Returns the scale and the new size ``(W', H')`` (rounded; the scale is the exact ratio of the rounded
        sizes, so it is isotropic up to rounding of the shorter side). ``long_side=None`` or a size not smaller
        than the image → identity (never upsample).
        """
        if long_side is None or long_side >= max(width, height):
            return cls(), (width, height)
        if long_side < 8:
            raise ValueError(f"PixelScale.for_long_side: long_side must be >= 8 pixels, got {long_side}")
        s = long_side / max(width, height)
        w2, h2 = max(1, round(width * s)), max(1, round(height * s))
        return cls(w2 / width, h2 / height), (w2, h2)

    def _apply(self, points, sx: float, sy: float):
        scale = (sx, sy)
        if isinstance(points, torch.Tensor):
            s = torch.tensor(scale, dtype=points.dtype, device=points.device)
        else:
            points = np.asarray(points, dtype=np.float64)
            s = np.asarray(scale)
        return (points + 0.5) * s - 0.5

    def to_scaled(self, points):
        """Original pixels ``(..., 2)`` → resized pixels (numpy or torch, differentiable)."""
        return points if self.is_identity else self._apply(points, self.sx, self.sy)

    def to_original(self, points):
        """Resized pixels ``(..., 2)`` → original pixels (numpy or torch, differentiable)."""
        return points if self.is_identity else self._apply(points, 1.0 / self.sx, 1.0 / self.sy)

    def intrinsics(self, K) -> np.ndarray:
        """The pinhole matrix of the resized image: ``K (3, 3)`` of the original pixels → ``(3, 3)`` float64.

        Focal lengths scale by ``(s_x, s_y)``; the principal point maps like any point (:meth:`to_scaled`, bit for
        bit, so it equals the rotation centre computed from ``K[:2, 2]``). The identity returns a float64 copy.
        """
        K = np.array(K, dtype=np.float64)
        if K.shape != (3, 3):
            raise ValueError(f"PixelScale.intrinsics: K must be (3, 3), got {K.shape}")
        if self.is_identity:
            return K
        out = K.copy()
        out[0, :2] *= self.sx
        out[1, :2] *= self.sy
        out[:2, 2] = self.to_scaled(K[:2, 2])
        return out

    def original_size(self, width: int, height: int) -> tuple[int, int]:
        """``(W, H)`` of the original image whose resized size is ``width × height`` (inverse of
        :meth:`for_long_side`'s rounding)."""
        if self.is_identity:
            return int(width), int(height)
        return max(1, round(width / self.sx)), max(1, round(height / self.sy))


def resize_image(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Resize an ``(H, W, C)`` image to ``size = (W', H')`` (area averaging when shrinking, bilinear otherwise)."""
    import cv2

    w2, h2 = size
    h, w = image.shape[:2]
    if (w2, h2) == (w, h):
        return image
    interp = cv2.INTER_AREA if w2 < w and h2 < h else cv2.INTER_LINEAR
    out = cv2.resize(image, (w2, h2), interpolation=interp)
    return out.reshape(h2, w2, *image.shape[2:])
