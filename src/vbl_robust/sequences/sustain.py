"""The sustained error of a sequence and the breach runs of its frames.

For per-frame errors ``e_0 … e_{F−1}`` (one θ held over the whole approach) the error *sustained over k
consecutive frames* is::

    S_k = max_{0 ≤ j ≤ F−k}  min_{j ≤ f < j+k} e_f

the largest error that every frame of some window of ``k`` consecutive frames reaches: a downstream filter that
rides out shorter bursts still sees ``S_k``. ``S_1`` is the worst frame, ``S_F`` the best one. The window of the
maximum is the first one reaching it. NaN errors propagate (the pipeline's errors are finite: failures count
:data:`~vbl_robust.constants.PENALTY_M`). ``min`` and ``max`` are subdifferentiable, so :func:`sustained_torch`
passes gradients to the frame and θ that set the value.
"""

from __future__ import annotations

import math

import numpy as np
import torch

__all__ = ["breach_runs", "breach_summary", "check_sustain", "sustained", "sustained_torch"]


def check_sustain(k, frames: int) -> int:
    """``k`` as an int in ``[1, frames]``; ``ValueError`` naming ``sustain`` otherwise."""
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 1 <= k <= frames:
        raise ValueError(f"sustain: need an integer k with 1 <= k <= {frames} (the sequence's frames), got {k!r}")
    return int(k)


def sustained(errors, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``S_k`` per column of ``errors`` ``(F, n)`` (or ``(F,)``): ``(values (n,), window start (n,) int)``.

    >>> sustained(np.array([1.0, 9.0, 8.0, 2.0, 7.0]), 2)
    (array([8.]), array([1]))
    """
    e = np.asarray(errors, dtype=np.float64)
    e = e[:, None] if e.ndim == 1 else e
    if e.ndim != 2:
        raise ValueError(f"sustained: errors must be (F,) or (F, n), got shape {np.shape(errors)}")
    k = check_sustain(k, e.shape[0])
    mins = np.lib.stride_tricks.sliding_window_view(e, k, axis=0).min(axis=-1)  # (F − k + 1, n)
    start = np.argmax(np.where(np.isnan(mins), np.inf, mins), axis=0)
    return mins[start, np.arange(e.shape[1])], start


def sustained_torch(errors: torch.Tensor, k: int) -> torch.Tensor:
    """``S_k`` per column of a tensor ``(F, n)``, differentiable (subgradient of min/max)."""
    if errors.ndim != 2:
        raise ValueError(f"sustained_torch: errors must be (F, n), got shape {tuple(errors.shape)}")
    k = check_sustain(k, errors.shape[0])
    return errors.unfold(0, k, 1).min(dim=-1).values.max(dim=0).values


def breach_runs(breached) -> list[tuple[int, int]]:
    """Runs of consecutive True frames: ``[(first frame, length), …]`` in order.

    >>> breach_runs([False, True, True, False, True])
    [(1, 2), (4, 1)]
    """
    b = np.asarray(breached, dtype=bool).reshape(-1)
    edges = np.diff(np.concatenate([[0], b.astype(np.int8), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    return [(int(s), int(e - s)) for s, e in zip(starts, ends, strict=True)]


def _at(values: np.ndarray, i: int | None) -> float | None:
    if i is None:
        return None
    v = float(values[i])
    return v if math.isfinite(v) else None


def breach_summary(errors, distances_m, times_s, k: int, eps_m: float) -> dict:
    """The breach facts of one sequence at one θ (per-frame ``errors`` ``(F,)``, metres).

    Returns ``{"sustained_m", "window_start", "breached_frames", "longest_run_frames", "longest_run_start",
    "longest_run_s", "breach_start_m", "breach_start_frame", "first_breach_m"}``: a frame is breached when its
    error exceeds ``eps_m``; the longest run of breached frames (its span in seconds from its first to its last
    frame, None without times); ``breach_start_*``: the first frame of the first run of at least ``k`` breached
    frames (the breach a filter cannot ride out) and its distance from the LTP; ``first_breach_m``: the distance
    of the first breached frame at all. Distances and frames are None when there is no such breach.
    """
    e = np.asarray(errors, dtype=np.float64).reshape(-1)
    d = np.asarray(distances_m, dtype=np.float64).reshape(-1)
    t = np.asarray(times_s, dtype=np.float64).reshape(-1)
    value, start = sustained(e, k)
    breached = e > eps_m
    runs = breach_runs(breached)
    longest = max(runs, key=lambda r: r[1]) if runs else None  # the first of the longest
    lasting = next((r for r in runs if r[1] >= k), None)
    first = int(np.argmax(breached)) if breached.any() else None
    span = None
    if longest is not None and np.isfinite(t).all():
        span = float(t[longest[0] + longest[1] - 1] - t[longest[0]])
    return {
        "sustained_m": float(value[0]),
        "window_start": int(start[0]),
        "breached_frames": int(breached.sum()),
        "longest_run_frames": longest[1] if longest else 0,
        "longest_run_start": longest[0] if longest else None,
        "longest_run_s": span,
        "breach_start_frame": lasting[0] if lasting else None,
        "breach_start_m": _at(d, lasting[0] if lasting else None),
        "first_breach_m": _at(d, first),
    }
