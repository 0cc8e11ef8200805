"""YOLO-pose label export for runway-corner keypoints.

Format (one line per object)::

    cls cx cy w h x1 y1 v1 x2 y2 v2 x3 y3 v3 x4 y4 v4

all coordinates normalised by the image width/height, keypoints in the order TR, TL, BL, BR (``kpt_shape:
[4, 3]``; a horizontal flip swaps TR↔TL and BL↔BR, hence ``flip_idx: [1, 0, 3, 2]``). ``v = 0`` marks a corner
outside the image, ``v = 2`` a visible one.

**Half-pixel convention.** This package's pixels follow OpenCV: pixel *centres* are at integer coordinates, so
the image spans ``[-0.5, W - 0.5]``. Ultralytics normalises with 0 at the left *edge* of the image and 1 at its
right edge (its resizing, flips and letterbox all scale edge coordinates). Hence::

    x_norm = (u + 0.5) / W        and back        u = x_norm · W − 0.5

:func:`to_edge` / :func:`from_edge` do the ``± 0.5``; forgetting it is a systematic 0.5-pixel offset at the
detector's input scale (≈ 1.5 px at 1024 px from a 320 px input).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

#: horizontal-flip permutation of the corners TR, TL, BL, BR
FLIP_IDX = (1, 0, 3, 2)
KPT_SHAPE = (4, 3)


def to_edge(uv: np.ndarray) -> np.ndarray:
    """OpenCV pixel coordinates (centres at integers) → edge coordinates (0 at the image's left/top edge)."""
    return np.asarray(uv, dtype=np.float64) + 0.5


def from_edge(xy: np.ndarray) -> np.ndarray:
    """Edge coordinates → OpenCV pixel coordinates; inverse of :func:`to_edge`."""
    return np.asarray(xy, dtype=np.float64) - 0.5


def widen_box(lo: np.ndarray, hi: np.ndarray, min_side: float) -> tuple[np.ndarray, np.ndarray]:
    """Grow the box ``[lo, hi]`` about its centre so that each side is at least ``min_side`` (unchanged if larger)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    half = np.maximum(hi - lo, float(min_side)) / 2
    mid = (lo + hi) / 2
    return mid - half, mid + half


def pose_label(corners_2d: np.ndarray, width: int, height: int, cls: int = 0, *, min_box: float = 0.0) -> str | None:
    """One YOLO-pose label line for runway corners.

    Args:
        corners_2d: (4, 2) corner pixels TR, TL, BL, BR in OpenCV convention (may lie outside the image).
        width, height: image size in pixels.
        cls: class index.
        min_box: minimum side of the labelled box in pixels. The box of a far runway is a few pixels wide at
            detector resolution; ultralytics' task-aligned assigner only takes anchors whose centres lie inside
            the box (stride 8 at best), so such a box gets zero or one positive anchor and the runway is learnt
            as background. Widening the *box* (about its centre, before clipping) gives it several anchors; the
            keypoints stay exact. (Side effect: ultralytics scales its keypoint loss by the box area, so corners of
            tiny runways are learnt with a looser tolerance; the second pass of the two-stage detector sees them
            large.)

    Returns:
        The label line, or ``None`` when no corner is inside the image and the runway box does not intersect it
        (nothing to label). The box is the corners' bounding box, widened to ``min_box``, clipped to the image.
    """
    c = np.asarray(corners_2d, dtype=np.float64).reshape(4, 2)
    if not np.all(np.isfinite(c)):
        return None
    e = to_edge(c)
    inside = (e[:, 0] >= 0) & (e[:, 0] <= width) & (e[:, 1] >= 0) & (e[:, 1] <= height)
    x1, y1 = np.clip(e.min(0), 0, [width, height])
    x2, y2 = np.clip(e.max(0), 0, [width, height])
    if x2 - x1 < 1.0 or y2 - y1 < 1.0:
        return None
    if min_box > 0:
        lo, hi = widen_box(e.min(0), e.max(0), min_box)
        x1, y1 = np.clip(lo, 0, [width, height])
        x2, y2 = np.clip(hi, 0, [width, height])
    vals = [(x1 + x2) / 2 / width, (y1 + y2) / 2 / height, (x2 - x1) / width, (y2 - y1) / height]
    parts = [str(int(cls))] + [f"{v:.7f}" for v in vals]
    for (x, y), vis in zip(e, inside, strict=True):
        if vis:
            parts += [f"{x / width:.7f}", f"{y / height:.7f}", "2"]
        else:
            parts += ["0", "0", "0"]
    return " ".join(parts)


def parse_pose_label(line: str, width: int, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`pose_label`: ``(box_xyxy (4,) edge px, corners (4, 2) OpenCV px, visible (4,) bool)``.

    Invisible corners come back as NaN.
    """
    v = np.array(line.split(), dtype=np.float64)
    if v.size != 5 + 12:
        raise ValueError(f"parse_pose_label: expected 17 fields, got {v.size}: {line!r}")
    cx, cy, w, h = v[1] * width, v[2] * height, v[3] * width, v[4] * height
    k = v[5:].reshape(4, 3)
    vis = k[:, 2] > 0
    corners = from_edge(k[:, :2] * [width, height])
    corners[~vis] = np.nan
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]), corners, vis


def write_data_yaml(root: str | Path, *, train: str = "images/train", val: str = "images/val") -> Path:
    """Write ``root/data.yaml`` for a one-class runway pose dataset (absolute ``path``, no ``download`` key)."""
    root = Path(root).resolve()
    text = (
        f"path: {root}\n"
        f"train: {train}\n"
        f"val: {val}\n"
        "kpt_shape: [4, 3]\n"
        "flip_idx: [1, 0, 3, 2]\n"
        "names:\n"
        "  0: runway\n"
    )
    p = root / "data.yaml"
    p.write_text(text)
    return p


def write_pose_images(
    items: Iterable[tuple[str, np.ndarray, np.ndarray]], root: str | Path, split: str, *, ext: str = "png",
    min_box: float = 0.0,
) -> int:
    """Write images and labels of one split under ``root/images/<split>`` and ``root/labels/<split>``.

    Args:
        items: ``(name, image (H, W, 3) uint8 RGB, corners_2d (4, 2) OpenCV px)`` triples; ``name`` must be a
            unique file stem. An image whose runway is entirely outside gets an empty label file (background).
        root: dataset root.
        split: ``"train"`` or ``"val"`` (any sub-directory name).
        ext: image file extension (``png`` is lossless).
        min_box: minimum side of the labelled boxes in pixels (see :func:`pose_label`).

    Returns:
        The number of images written.
    """
    import cv2

    root = Path(root)
    img_dir, lbl_dir = root / "images" / split, root / "labels" / split
    img_dir.mkdir(parents=True, exist_ok=True)
    lbl_dir.mkdir(parents=True, exist_ok=True)
    n = 0
    for name, image, corners in items:
        img = np.asarray(image)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"write_pose_images: image {name!r} must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
        h, w = img.shape[:2]
        if not cv2.imwrite(str(img_dir / f"{name}.{ext}"), np.ascontiguousarray(img[:, :, ::-1])):
            raise ValueError(f"write_pose_images: could not write {img_dir / f'{name}.{ext}'}")
        line = pose_label(corners, w, h, min_box=min_box)
        (lbl_dir / f"{name}.txt").write_text("" if line is None else line + "\n")
        n += 1
    return n
