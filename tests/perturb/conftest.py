"""Shared test images: a small approach-like picture (sky gradient, textured ground, a bright runway quad)."""

import cv2
import numpy as np
import pytest


def realish_image(height: int = 120, width: int = 160, seed: int = 0) -> np.ndarray:
    """(H, W, 3) uint8 RGB with a horizon, smooth texture, a drawn quadrilateral and sharp edges."""
    rng = np.random.default_rng(seed)
    img = np.zeros((height, width, 3), np.float32)
    horizon = int(0.35 * height)
    img[:horizon] = np.linspace(0.55, 0.85, horizon, dtype=np.float32)[:, None, None] * np.array([0.7, 0.8, 1.0])
    ground = cv2.GaussianBlur(rng.random((height - horizon, width, 3)).astype(np.float32), (0, 0), 1.5)
    img[horizon:] = 0.25 + 0.35 * ground * np.array([0.6, 0.9, 0.5], np.float32)
    quad = np.array([[0.55, 0.45], [0.45, 0.45], [0.25, 0.95], [0.75, 0.95]]) * [width, height]
    cv2.fillPoly(img, [np.round(quad * 16).astype(np.int32)], (0.3, 0.3, 0.32), lineType=cv2.LINE_AA, shift=4)
    cv2.line(img, (int(0.5 * width), int(0.5 * height)), (int(0.5 * width), int(0.9 * height)), (0.95, 0.95, 0.95), 1)
    return np.clip(np.round(img * 255), 0, 255).astype(np.uint8)


@pytest.fixture
def image() -> np.ndarray:
    return realish_image()


@pytest.fixture
def make_image():
    """The :func:`realish_image` factory, for tests that need other sizes or seeds."""
    return realish_image
