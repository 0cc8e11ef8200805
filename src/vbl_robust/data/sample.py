"""The :class:`Sample`: one image with everything the pipeline needs to score a pose estimate.

All geometry is in the runway frame of :mod:`vbl_robust.geometry.camera` (metres; corners TR, TL, BL, BR).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


def load_rgb(path: str | Path) -> np.ndarray:
    """Read an image file as (H, W, 3) uint8 RGB; ``FileNotFoundError``/``ValueError`` naming the file otherwise."""
    import cv2

    p = Path(path)
    try:
        found = p.is_file()
    except OSError as exc:  # e.g. a name too long for the file system
        raise ValueError(f"{p}: unreadable image path ({exc.strerror or exc})") from None
    if not found:
        raise FileNotFoundError(f"{p}: image file not found")
    bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{p}: unreadable image (not a format OpenCV can decode)")
    return np.ascontiguousarray(bgr[:, :, ::-1])


@dataclass(eq=False)
class Sample:
    """One approach image with exact geometry.

    Attributes:
        id: identifier, unique within a dataset (LARD: the ``image`` path relative to the dataset root).
        K: (3, 3) pinhole intrinsics of the image as stored (pixels, OpenCV convention).
        corners_3d: (4, 3) runway corners TR, TL, BL, BR in the runway frame, metres.
        corners_2d: (4, 2) ground-truth pixel coordinates of those corners (float; may lie outside the image).
        position: (3,) true camera position in the runway frame, metres.
        R: (3, 3) camera → runway rotation (columns: forward, left, up), or None if unknown.
        width, height: image size in pixels.
        image_path: file the pixels come from (read lazily), or None when ``image`` was given in memory.
        meta: free-form extra fields (LARD row values, envelope name, …).
    """

    id: str
    K: np.ndarray
    corners_3d: np.ndarray
    corners_2d: np.ndarray
    position: np.ndarray
    width: int
    height: int
    R: np.ndarray | None = None
    image_path: Path | None = None
    meta: dict = field(default_factory=dict)
    _image: np.ndarray | None = field(default=None, repr=False)
    _loader: Callable[[], np.ndarray] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        self.corners_3d = np.asarray(self.corners_3d, dtype=np.float64).reshape(4, 3)
        self.corners_2d = np.asarray(self.corners_2d, dtype=np.float64).reshape(4, 2)
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        if self.R is not None:
            self.R = np.asarray(self.R, dtype=np.float64).reshape(3, 3)
        if self.image_path is not None:
            self.image_path = Path(self.image_path)

    @property
    def image(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB pixels, loaded on first access."""
        if self._image is None:
            if self._loader is not None:
                img = self._loader()
            elif self.image_path is not None:
                img = load_rgb(self.image_path)
            else:
                raise ValueError(f"sample {self.id}: has no pixels (no image and no image_path)")
            if img.shape[:2] != (self.height, self.width):
                raise ValueError(
                    f"{self.image_path or self.id}: image is {img.shape[1]}x{img.shape[0]} px, "
                    f"metadata says {self.width}x{self.height}"
                )
            self._image = img
        return self._image

    @image.setter
    def image(self, value: np.ndarray) -> None:
        self._image = value

    def drop_pixels(self) -> None:
        """Forget cached pixels (they are reloaded on demand) to bound memory in long campaigns."""
        if self.image_path is not None or self._loader is not None:
            self._image = None

    @property
    def slant_distance_m(self) -> float:
        """Distance from the camera to the LTP (runway-frame origin), metres."""
        return float(np.linalg.norm(self.position))

    def corners_in_image(self, margin_px: float = 0.0) -> bool:
        """True when all four ground-truth corners lie inside the image (with an optional inward margin)."""
        u, v = self.corners_2d[:, 0], self.corners_2d[:, 1]
        return bool(
            np.all(u >= margin_px) and np.all(u <= self.width - 1 - margin_px)
            and np.all(v >= margin_px) and np.all(v <= self.height - 1 - margin_px)
        )
