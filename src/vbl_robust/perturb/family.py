"""The contract of a perturbation family: the maps one registry entry carries.

A family is one object (a :class:`Family`) in the module that holds its maths, named by one entry of
:data:`vbl_robust.perturb.registry.PERTURBATIONS` (``family="module:NAME"``). :class:`~vbl_robust.perturb.compose.Perturbation`,
the view sampler and the training augmentation only iterate the registry and call these methods; none of them
names a family. A new family is therefore its module plus one registry line.

Values: every method gets ``v``, a dict ``{parameter name: value}`` holding **only the family's parameters that
the box has** (a family may read several, e.g. roll, pitch and yaw of the camera attitude); absent ones keep their
identity. Values are floats in :meth:`Family.frame_numpy` (one frame at a time) and ``(N,)`` columns (tensors on
the images' device, or NumPy arrays in :meth:`Family.points`) elsewhere.

What each kind implements (``kind`` lives in the registry entry):

* ``geometric`` — :meth:`~Family.frame_numpy`, :meth:`~Family.frame_torch`, :meth:`~Family.points` (forward) and
  :meth:`~Family.source_coords` (inverse, for views sampled straight from the source); optionally
  :meth:`~Family.source_matrix` (the inverse as homographies: the black-box path then warps with OpenCV);
* ``optical`` and ``noise`` — the two frame maps (they act on whole frames);
* ``photometric`` — the two frame maps and :meth:`~Family.pointwise` (on pixel values sampled from the
  geometrically perturbed frame, with the frame's grey mean ``stats`` where the family needs it:
  :attr:`~Family.needs_stats`; a family before such a one says how it moves that mean: :meth:`~Family.stats_after`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Family", "FrameContext", "Pointwise", "identity_like"]


@dataclass
class FrameContext:
    """What the maps know about the frame they act on.

    Attributes:
        center: the principal point ``(cx, cy)`` in the frame's pixels (a tensor in :meth:`Family.source_coords`),
            or ``None`` (the roll then defaults to the frame's centre).
        K: the ``(3, 3)`` pinhole matrix of the frame's pixels (a tensor in :meth:`Family.source_coords`), or
            ``None``.
        scale: the :class:`~vbl_robust.perturb.resample.PixelScale` from the sample's pixels to the frame's.
        rng: training only: the noise family then draws a fresh standard-normal pattern from it instead of the
            audit's one fixed seeded pattern.
    """

    center: Any = None
    K: Any = None
    scale: Any = None
    rng: Any = None


class Family:
    """Base class of a family's maps (module docstring). Subclasses set :attr:`params` and implement what their
    kind needs; the defaults below refuse, naming the family."""

    #: the registry names this family reads, in the registry's order
    params: tuple[str, ...] = ()
    #: the pointwise map needs the grey mean of the geometrically perturbed frame
    needs_stats: bool = False
    #: parameters that need the intrinsics ``K`` (not only the principal point)
    needs_K: tuple[str, ...] = ()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(self.params)})"

    def _missing(self, what: str):
        raise NotImplementedError(f"{self!r} has no {what}")

    def frame_numpy(self, frame, v: dict, ctx: FrameContext, out):
        """One frame ``(H, W, C)`` float32 → the perturbed frame, written into ``out`` where possible (``out`` is
        ``frame`` itself for every kind but ``geometric``); returns the result."""
        self._missing("NumPy frame map")

    def frame_torch(self, x, v: dict, ctx: FrameContext):
        """Frames ``(B, C, H, W)`` (``B`` = 1 broadcasts over the rows of ``v``) → ``(N, C, H, W)``, differentiable
        w.r.t. the values."""
        self._missing("torch frame map")

    def points(self, points, v: dict, ctx: FrameContext):
        """``geometric``: pixel points ``(P, 2)`` or ``(N, P, 2)`` → ``(N, P, 2)`` where the content moves."""
        self._missing("point map")

    def source_coords(self, qu, qv, v: dict, ctx: FrameContext):
        """``geometric``: OpenCV coordinates in the perturbed frame ``(B, …)`` → source coordinates (unreflected)."""
        self._missing("source-coordinate map")

    def source_matrix(self, v: dict, ctx: FrameContext):
        """``geometric``, optional: the inverse map as homographies ``(N, 3, 3)`` float64 NumPy (OpenCV pixels of the
        perturbed frame → source pixels, before reflection) for NumPy values; ``None`` (the default) when it is not
        one: views are then sampled through :meth:`source_coords` (see :mod:`vbl_robust.perturb.warp`)."""
        return None

    def pointwise(self, values, v: dict, stats):
        """``photometric``: pixel values ``(B, C, …)`` sampled from the geometrically perturbed frames → perturbed
        values; ``stats`` ``(B,)`` the frames' grey means (given when :attr:`needs_stats`)."""
        self._missing("pointwise map")

    def pointwise_(self, values, v: dict, stats):
        """:meth:`pointwise` in place on ``values`` (no gradient: the black-box path, one view at a time while it is
        in the cache); the default copies :meth:`pointwise`'s result."""
        return values.copy_(self.pointwise(values, v, stats))

    def stats_after(self, stats, v: dict, channels: int):
        """The frames' grey means after this family (``None``: not known exactly; a later family that needs them
        is then refused)."""
        return None


def identity_like(column, value: float):
    """An ``(N,)`` column of ``value`` shaped, typed and placed like ``column`` (tensor or NumPy)."""
    if hasattr(column, "new_full"):
        return column.new_full(column.shape, value)
    import numpy as np

    return np.full(column.shape, value, dtype=np.float64)


class Pointwise(Family):
    """A one-parameter ``photometric`` family from its two functions: ``torch_fn(images, values (B,))`` and
    ``numpy_fn(frame, value, out=)`` (the same map on whole frames and on sampled pixel values), and optionally
    ``inplace_fn(images, values (B,))``, ``torch_fn`` in place with the same operations (the same values)."""

    def __init__(self, name: str, torch_fn, numpy_fn, inplace_fn=None):
        self.params = (name,)
        self._torch, self._numpy, self._inplace = torch_fn, numpy_fn, inplace_fn

    def frame_numpy(self, frame, v, ctx, out):
        return self._numpy(frame, v[self.params[0]], out=out)

    def frame_torch(self, x, v, ctx):
        return self._torch(x, v[self.params[0]].to(x.device))

    def pointwise(self, values, v, stats):
        return self._torch(values, v[self.params[0]])

    def pointwise_(self, values, v, stats):
        if self._inplace is None:
            return super().pointwise_(values, v, stats)
        return self._inplace(values, v[self.params[0]])
