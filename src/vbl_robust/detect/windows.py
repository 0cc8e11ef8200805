"""Detector-side geometry: which square windows of an image a detector looks at.

Windows are ``(x0, y0, side)`` in image edge coordinates (see :mod:`vbl_robust.perturb.views`, which produces
their pixels): the centred letterbox of the whole frame, and square crops around a box of corners.
"""

from __future__ import annotations

import torch

__all__ = ["box_window", "corner_box", "letterbox_window"]


def letterbox_window(height: int, width: int) -> tuple[float, float, float]:
    """Window ``(x0, y0, side)`` of the centred square letterbox of an ``height × width`` image."""
    side = float(max(height, width))
    return (-(side - width) / 2.0, -(side - height) / 2.0, side)


def corner_box(corners: torch.Tensor) -> torch.Tensor:
    """(B, 4) xyxy boxes in edge coordinates around (B, P, 2) OpenCV-pixel corners."""
    e = corners + 0.5
    return torch.cat([e.amin(1), e.amax(1)], 1)


def box_window(
    box_xyxy: torch.Tensor, *, margin: float = 1.5, min_side: float = 64.0, max_side: float | None = None
) -> torch.Tensor:
    """Square crop windows around boxes.

    Args:
        box_xyxy: (B, 4) boxes in edge coordinates (e.g. the bounding box of the four corners).
        margin: side = ``margin · max(w, h)`` …
        min_side: … but at least this many image pixels (a far runway is a few pixels; the crop keeps context);
        max_side: … and at most this (None: unbounded).

    Returns:
        (B, 3) windows ``(x0, y0, side)`` centred on the boxes.
    """
    c = (box_xyxy[:, :2] + box_xyxy[:, 2:]) / 2
    wh = (box_xyxy[:, 2:] - box_xyxy[:, :2]).abs()
    side = (margin * wh.max(dim=1).values).clamp(min=min_side)
    if max_side is not None:
        side = side.clamp(max=max_side)
    return torch.cat([c - side[:, None] / 2, side[:, None]], dim=1)
