"""Apply the perturbations named by a :class:`~vbl_robust.space.ParameterBox` to one image, batched over θ.

Column ``i`` of a θ array ``(N, d)`` is the parameter ``box.names[i]`` in real units (see :mod:`vbl_robust.space`).
Known names, their meaning and their order of application are the registry's (:mod:`.registry`); each
family's maths is its :class:`~vbl_robust.perturb.family.Family` (:mod:`.family`). :class:`Perturbation` only
iterates the registry: it names no family. A parameter absent from the box keeps its identity value.

Units: angles in degrees; ``blur_px`` and ``motion_blur_px`` in pixels **of the sample's image** (the composer
scales them to a resized source with the :class:`~vbl_robust.perturb.resample.PixelScale` it is given, so one θ means the
same physical blur for every detector resolution); ``brightness``, ``haze``, ``noise_std`` as fractions of full
scale; ``contrast`` and ``gamma`` dimensionless.

Camera: the attitude needs the pinhole ``K`` of the pixels it warps (``K=``, e.g.
:meth:`PixelScale.intrinsics <vbl_robust.perturb.resample.PixelScale.intrinsics>` of the sample's ``K``); roll needs only
the principal point (``center=``, or ``K``'s).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import torch

from vbl_robust.space import ParameterBox

from .family import Family, FrameContext
from .photometric import gray_mean
from .registry import PERTURBATIONS, FamilyKind, family_of, known
from .resample import PixelScale
from .warp import empty_output

__all__ = ["Perturbation"]


def _groups(names: Sequence[str]) -> list[tuple[Family, str, tuple[str, ...]]]:
    """The families of ``names`` in the registry's order: ``(family, kind, its parameters in the box)``."""
    out: dict[int, tuple[Family, str, list[str]]] = {}
    for name in PERTURBATIONS:
        if name in names:
            fam = family_of(name)
            out.setdefault(id(fam), (fam, PERTURBATIONS[name].kind, []))[2].append(name)
    return [(fam, kind, tuple(params)) for fam, kind, params in out.values()]


class Perturbation:
    """The image and point transform ``T(·; θ)`` for the parameters of a box.

    >>> from vbl_robust.space import ParameterBox
    >>> p = Perturbation(ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)}))
    >>> img = np.zeros((8, 8, 3), np.uint8)
    >>> p.images(img, np.array([[10.0, 1.2], [0.0, 1.0]])).shape
    (2, 8, 8, 3)

    Camera arguments of the image and point methods (keyword-only):

    * ``center`` — the principal point ``(cx, cy)`` in the image's pixels, the centre of the roll (``None``:
      ``K``'s, else ``(W/2, H/2)``);
    * ``K`` — the ``(3, 3)`` pinhole matrix of the image's pixels; required by ``pitch_deg`` / ``yaw_deg``. When
      both are given they must agree;
    * ``scale`` — the :class:`~vbl_robust.perturb.resample.PixelScale` from the sample's pixels to the image's (blur
      lengths and the noise grid are in the sample's pixels); ``None`` = the image is the sample's.
    """

    def __init__(self, box: ParameterBox | Sequence[str]):
        names = tuple(box.names) if isinstance(box, ParameterBox) else tuple(box)
        if not names:
            raise ValueError(f"Perturbation: no parameters given; known perturbations: {known()}")
        for name in names:
            if name not in PERTURBATIONS:
                raise ValueError(f"Perturbation: unknown parameter {name!r}; known perturbations: {known()}")
        if len(set(names)) != len(names):
            raise ValueError(f"Perturbation: duplicate parameter names in {names}")
        if isinstance(box, ParameterBox):
            for name, lo, hi in zip(box.names, box.lower, box.upper, strict=True):
                spec = PERTURBATIONS[name]
                if lo < spec.minimum:
                    raise ValueError(f"Perturbation: lower bound of {name!r} must be >= {spec.minimum}, got {lo}")
                if hi > spec.maximum:
                    raise ValueError(f"Perturbation: upper bound of {name!r} must be <= {spec.maximum}, got {hi}")
        self.names = names
        self._index = {n: i for i, n in enumerate(names)}
        self._groups = _groups(names)

    def __repr__(self) -> str:
        return f"Perturbation({list(self.names)})"

    @property
    def dim(self) -> int:
        return len(self.names)

    def has(self, name: str) -> bool:
        """True when the box has the parameter ``name``."""
        return name in self._index

    def _kinds(self) -> set[str]:
        return {kind for _, kind, _ in self._groups}

    def _of_kind(self, *kinds: str) -> list[tuple[Family, tuple[str, ...]]]:
        return [(fam, params) for fam, kind, params in self._groups if kind in kinds]

    def _values(self, theta, params: tuple[str, ...], like=None) -> dict:
        """``{name: column}`` of θ for ``params`` (on ``like``'s device when given)."""
        return {n: self.column(theta, n) if like is None else _column_tensor(self.column(theta, n), like)
                for n in params}

    @property
    def is_geometric(self) -> bool:
        """True when some parameter moves pixels (keypoints must then be moved too)."""
        return FamilyKind.GEOMETRIC in self._kinds()

    @property
    def needs_K(self) -> tuple[str, ...]:
        """The box's parameters that need the intrinsics ``K`` (not only the principal point)."""
        return tuple(n for fam, _, params in self._groups for n in params if n in fam.needs_K)

    @property
    def needs_frame(self) -> bool:
        """True when some family acts on whole perturbed frames (``optical`` convolutions, the ``noise`` pattern
        of the sensor grid): views must then be cut from rendered frames (see
        :class:`~vbl_robust.perturb.views.ViewSampler`)."""
        return bool(self._kinds() & {FamilyKind.OPTICAL, FamilyKind.NOISE})

    # -- θ handling --------------------------------------------------------------------------------------
    def check_theta(self, theta):
        """θ as ``(N, d)`` (a 1-D θ of length d is one row); ``ValueError`` on a wrong shape, non-finite values
        or values outside a family's domain."""
        t = theta if isinstance(theta, torch.Tensor) else np.asarray(theta, dtype=np.float64)
        if t.ndim == 1 and t.shape[0] == self.dim:
            t = t[None, :]
        if t.ndim != 2 or t.shape[1] != self.dim:
            raise ValueError(f"theta must have shape (N, {self.dim}) for parameters {self.names}, got {tuple(t.shape)}")
        finite = bool(torch.isfinite(t).all()) if isinstance(t, torch.Tensor) else bool(np.isfinite(t).all())
        if not finite:
            raise ValueError(f"theta must be finite, got non-finite values for parameters {self.names}")
        for name, i in self._index.items():  # outside the box is allowed; outside the family's domain is not
            spec = PERTURBATIONS[name]
            col = t[:, i]
            if spec.minimum > -np.inf and bool((col < spec.minimum).any()):
                raise ValueError(f"theta: {name} must be >= {spec.minimum:g}, got {float(col.min()):g}")
            if spec.maximum < np.inf and bool((col > spec.maximum).any()):
                raise ValueError(f"theta: {name} must be <= {spec.maximum:g}, got {float(col.max()):g}")
        return t

    def column(self, theta, name: str):
        """Column ``(N,)`` of θ for ``name`` (identity value if the box has no such parameter)."""
        i = self._index.get(name)
        if i is not None:
            return theta[:, i]
        ident = PERTURBATIONS[name].identity
        if isinstance(theta, torch.Tensor):
            return torch.full((theta.shape[0],), ident, dtype=theta.dtype, device=theta.device)
        return np.full(theta.shape[0], ident)

    def _camera(self, center, K):
        """``(center, K)`` resolved: K's principal point when only K is given; ``ValueError`` when pitch/yaw lack
        K or the two disagree. ``center`` stays ``None`` (the roll's default) when neither is given."""
        if K is not None:
            K = np.asarray(K.detach().cpu() if isinstance(K, torch.Tensor) else K, dtype=np.float64)
            if K.shape != (3, 3) or not np.isfinite(K).all():
                raise ValueError(f"Perturbation: K must be a finite (3, 3) pinhole matrix, got shape {K.shape}")
            if center is None:
                center = (float(K[0, 2]), float(K[1, 2]))
            elif not np.allclose(np.asarray(center, np.float64).reshape(-1), K[:2, 2], rtol=0.0, atol=1e-9):
                raise ValueError(f"Perturbation: center {center!r} is not the principal point {K[:2, 2].tolist()} "
                                 "of K")
        elif self.needs_K:
            raise ValueError(f"Perturbation: {' and '.join(self.needs_K)} need the camera intrinsics: pass K (3, 3) "
                             "in the image's pixels")
        return center, K

    @staticmethod
    def _scale(scale) -> PixelScale:
        if scale is None:
            return PixelScale()
        if not isinstance(scale, PixelScale):
            raise ValueError(f"Perturbation: scale must be a PixelScale, got {type(scale).__name__}")
        return scale

    # -- images --------------------------------------------------------------------------------------------
    def images(self, image, theta, *, center=None, K=None, scale=None):
        """Perturbed copies of one image, one per row of θ.

        Dispatches on the types: a NumPy image with a NumPy θ uses :meth:`images_numpy`; anything else
        :meth:`images_torch`.
        """
        if isinstance(image, np.ndarray) and not isinstance(theta, torch.Tensor):
            return self.images_numpy(image, theta, center=center, K=K, scale=scale)
        return self.images_torch(image, theta, center=center, K=K, scale=scale)

    __call__ = images

    def images_numpy(self, image: np.ndarray, theta, *, center=None, K=None, scale=None,
                     channels_first: bool = False) -> np.ndarray:
        """No-gradient path (OpenCV): ``image (H, W, C)`` uint8 or float in [0, 1] → ``(N, H, W, C)`` float32, or
        ``(N, C, H, W)`` with ``channels_first`` (each frame rendered in one scratch frame and split into its planes
        while in the cache: the layout a network reads, without a strided copy of the batch).

        Camera arguments: see the class docstring.
        """
        if not isinstance(image, np.ndarray) or image.ndim != 3:
            raise ValueError(f"images_numpy: image must be an (H, W, C) array, got {getattr(image, 'shape', image)!r}")
        t = self.check_theta(np.asarray(theta, dtype=np.float64))
        h, w = image.shape[:2]
        center, K = self._camera(center, K)
        sc = self._scale(scale)
        base = image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else image.astype(np.float32, copy=False)
        ctx = FrameContext(center=center, K=K, scale=sc)
        steps = [(fam, kind == FamilyKind.GEOMETRIC, params, self._values(t, params),
                  tuple(PERTURBATIONS[n].identity for n in params)) for fam, kind, params in self._groups]
        n, (_, _, c) = t.shape[0], base.shape
        out = empty_output(n, c, h, w).numpy() if channels_first else empty_output(n, h, w, c).numpy()
        scratch = np.empty_like(base) if channels_first else None
        for k in range(t.shape[0]):
            frame, src = (out[k] if scratch is None else scratch), base
            for fam, moves, params, cols, identity in steps:
                v = {n: cols[n][k] for n in params}
                if all(v[n] == i for n, i in zip(params, identity, strict=True)):
                    continue  # the identity: nothing to compute
                if moves:  # a warp reads its source and writes the frame
                    if src is frame:
                        src = frame.copy()
                    res = fam.frame_numpy(src, v, ctx, frame)
                else:  # the other kinds work in place
                    if src is not frame:
                        frame[...] = src
                    res = fam.frame_numpy(frame, v, ctx, frame)
                if not np.shares_memory(res, frame):  # OpenCV could not write in place (e.g. 1 channel)
                    frame[...] = res
                src = frame
            if src is not frame:
                frame[...] = src
            if scratch is not None:
                cv2.mixChannels([scratch], list(out[k]), [i for ch in range(c) for i in (ch, ch)])
        return out

    def images_torch(self, image, theta, *, center=None, K=None, scale=None) -> torch.Tensor:
        """Differentiable path: ``image (C, H, W)`` / ``(1, C, H, W)`` tensor (float in [0, 1] or uint8) or an
        ``(H, W, C)`` uint8 array → ``(N, C, H, W)``, differentiable w.r.t. θ (a tensor ``(N, d)``).

        Computed in the image's float dtype (float32 for uint8 input); θ may be float64 — the gradient flows back.
        Camera arguments: see the class docstring.
        """
        x = _as_chw_tensor(image)
        t = self.check_theta(theta if isinstance(theta, torch.Tensor) else torch.as_tensor(np.asarray(theta)))
        t = t.to(x.device)  # θ follows the image to its device (differentiable: the gradient flows back)
        n = t.shape[0]
        center, K = self._camera(center, K)
        sc = self._scale(scale)
        ctx = FrameContext(center=center, K=K, scale=sc)
        for fam, _, params in self._groups:
            x = fam.frame_torch(x, self._values(t, params), ctx)
        if x.shape[0] != n:
            x = x.expand(n, -1, -1, -1)
        return x

    # -- what the view sampler needs (vbl_robust.perturb.views.ViewSampler) ---------------------------------
    @property
    def has_photometric(self) -> bool:
        """True when some parameter changes pixel values pointwise (after the geometry)."""
        return FamilyKind.PHOTOMETRIC in self._kinds()

    @property
    def needs_stats(self) -> bool:
        """True when a photometric family needs statistics of the whole frame (the contrast's grey mean)."""
        return any(fam.needs_stats for fam, _ in self._of_kind(FamilyKind.PHOTOMETRIC))

    def source_coords(self, qu: torch.Tensor, qv: torch.Tensor, theta, center: torch.Tensor, K=None):
        """Inverse geometric map: perturbed-image OpenCV coordinates ``(B, …)`` → source coordinates (unreflected),
        for θ rows ``(B, d)``; the identity when no parameter is geometric. ``K`` (3, 3): required by the attitude
        homography (``pitch_deg``/``yaw_deg``)."""
        ctx = FrameContext(center=center, K=K)
        for fam, params in reversed(self._of_kind(FamilyKind.GEOMETRIC)):  # the inverse: last map first
            qu, qv = fam.source_coords(qu, qv, self._values(theta, params, qu), ctx)
        return qu, qv

    def source_matrices(self, theta: np.ndarray, center, K=None) -> np.ndarray | None:
        """The inverse geometric map of NumPy θ rows ``(B, d)`` as homographies ``(B, 3, 3)`` float64 (perturbed-frame
        OpenCV pixels → source pixels, unreflected; :meth:`source_coords` as matrices), or None when some geometric
        family has none (:meth:`Family.source_matrix <vbl_robust.perturb.family.Family.source_matrix>`). The
        identity when no parameter is geometric."""
        m = np.broadcast_to(np.eye(3), (theta.shape[0], 3, 3))
        ctx = FrameContext(center=center, K=K)
        for fam, params in reversed(self._of_kind(FamilyKind.GEOMETRIC)):  # the inverse: last map first
            h = fam.source_matrix(self._values(theta, params), ctx)
            if h is None:
                return None
            m = h @ m
        return np.array(m, dtype=np.float64)

    def photometric_stats(self, values: torch.Tensor) -> torch.Tensor:
        """``(B,)`` statistics the photometric families need, from samples ``(B, 3, n, n)`` of the geometrically
        perturbed frames (the grey mean of the contrast)."""
        return gray_mean(values)

    def photometric_torch(self, values: torch.Tensor, theta, stats: torch.Tensor | None, *,
                          inplace: bool = False) -> torch.Tensor:
        """The pointwise photometric families (haze, contrast, brightness, gamma) on pixel values ``(B, 3, …)`` of
        the geometrically perturbed frames; ``stats`` from :meth:`photometric_stats` (needed by the contrast).
        ``inplace``: overwrite ``values`` (no gradient; the same values)."""
        for fam, params in self._of_kind(FamilyKind.PHOTOMETRIC):
            v = self._values(theta, params, values)
            if fam.needs_stats and stats is None:
                raise ValueError(f"Perturbation.photometric_torch: {fam!r} needs the frames' grey means (stats), "
                                 "and no exact grey mean is known at this point")
            values = fam.pointwise_(values, v, stats) if inplace else fam.pointwise(values, v, stats)
            if stats is not None:
                stats = fam.stats_after(stats, v, values.shape[1])
        return values

    # -- points --------------------------------------------------------------------------------------------
    def points(self, points, theta, *, center=None, K=None):
        """Move pixel points ``(P, 2)`` or ``(N, P, 2)`` as the image content moves: ``(N, P, 2)``.

        NumPy in, NumPy out; a tensor (points or θ) gives a tensor differentiable w.r.t. θ. ``center`` / ``K`` as
        in :meth:`images` (one is required by a geometric box: points carry no image size). A point that the
        attitude puts behind the camera is NaN. Only the geometric families move points.
        """
        t = self.check_theta(theta)
        if self.is_geometric:
            center, K = self._camera(center, K)
            ctx = FrameContext(center=center, K=K)
            for fam, params in self._of_kind(FamilyKind.GEOMETRIC):
                points = fam.points(points, self._values(t, params), ctx)
            return points
        n = t.shape[0]
        if isinstance(points, torch.Tensor) or isinstance(t, torch.Tensor):
            p = torch.as_tensor(points, dtype=t.dtype if isinstance(t, torch.Tensor) else torch.float64)
            return p[None].expand(n, -1, -1).clone() if p.ndim == 2 else p.clone()
        p = np.asarray(points, dtype=np.float64)
        return np.broadcast_to(p, (n, *p.shape[-2:])).copy()


def _column_tensor(col, like: torch.Tensor | None = None) -> torch.Tensor:
    """A θ column as a tensor, on ``like``'s device when given (float64 for a NumPy column)."""
    t = col if isinstance(col, torch.Tensor) else torch.as_tensor(np.asarray(col, dtype=np.float64))
    return t if like is None else t.to(like.device)


def _as_chw_tensor(image) -> torch.Tensor:
    if isinstance(image, np.ndarray):
        if image.ndim != 3:
            raise ValueError(f"images_torch: a NumPy image must be (H, W, C), got {image.shape}")
        image = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)
    if not isinstance(image, torch.Tensor):
        raise ValueError(f"images_torch: image must be a tensor or an array, got {type(image).__name__}")
    if image.ndim == 3:
        image = image[None]
    if image.ndim != 4 or image.shape[0] != 1:
        raise ValueError(f"images_torch: image must be (C, H, W) or (1, C, H, W), got {tuple(image.shape)}")
    if image.dtype == torch.uint8:
        image = image.to(torch.float32) / 255.0
    if not image.is_floating_point():
        raise ValueError(f"images_torch: image must be float in [0, 1] or uint8, got {image.dtype}")
    return image
