"""Apply the perturbations named by a :class:`~vbl_robust.space.ParameterBox` to one image, batched over θ.

Column ``i`` of a θ array ``(N, d)`` is the parameter ``box.names[i]`` in real units (see :mod:`vbl_robust.space`).
Known names are in :data:`PERTURBATIONS`; a parameter absent from the box keeps its identity value.

Order: the geometric perturbation (camera roll) first, then the photometric one (contrast) on the rolled frame —
the camera takes a rolled picture whose contrast then changes. The order matters only through the grayscale mean
of the contrast, which sees the reflected borders.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from vbl_robust.space import ParameterBox

from .geometric import roll, roll_numpy, roll_points, roll_source_coords
from .photometric import contrast, contrast_about, contrast_numpy, gray_mean

__all__ = ["PERTURBATIONS", "Perturbation", "PerturbationSpec"]


@dataclass(frozen=True)
class PerturbationSpec:
    """What a parameter name means: ``kind`` (``"geometric"`` moves points), identity value, lowest valid value."""

    name: str
    kind: str
    identity: float
    minimum: float
    description: str


#: The parameter names a box may use, in the order they are applied.
PERTURBATIONS: dict[str, PerturbationSpec] = {
    "roll_deg": PerturbationSpec(
        "roll_deg", "geometric", 0.0, -np.inf,
        "camera roll about the optical axis, degrees, positive = right wing down (image turns counter-clockwise)",
    ),
    "contrast": PerturbationSpec(
        "contrast", "photometric", 1.0, 0.0, "contrast factor (torchvision definition), 1 = unchanged",
    ),
}


def _known() -> str:
    return ", ".join(PERTURBATIONS)


class Perturbation:
    """The image and point transform ``T(·; θ)`` for the parameters of a box.

    >>> from vbl_robust.space import ParameterBox
    >>> p = Perturbation(ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)}))
    >>> img = np.zeros((8, 8, 3), np.uint8)
    >>> p.images(img, np.array([[10.0, 1.2], [0.0, 1.0]])).shape
    (2, 8, 8, 3)
    """

    def __init__(self, box: ParameterBox | Sequence[str]):
        names = tuple(box.names) if isinstance(box, ParameterBox) else tuple(box)
        if not names:
            raise ValueError(f"Perturbation: no parameters given; known perturbations: {_known()}")
        for name in names:
            if name not in PERTURBATIONS:
                raise ValueError(f"Perturbation: unknown parameter {name!r}; known perturbations: {_known()}")
        if len(set(names)) != len(names):
            raise ValueError(f"Perturbation: duplicate parameter names in {names}")
        if isinstance(box, ParameterBox):
            for name, lo in zip(box.names, box.lower, strict=True):
                if lo < PERTURBATIONS[name].minimum:
                    raise ValueError(
                        f"Perturbation: lower bound of {name!r} must be >= {PERTURBATIONS[name].minimum}, got {lo}"
                    )
        self.names = names
        self._index = {n: i for i, n in enumerate(names)}

    def __repr__(self) -> str:
        return f"Perturbation({list(self.names)})"

    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def is_geometric(self) -> bool:
        """True when some parameter moves pixels (keypoints must then be moved too)."""
        return any(PERTURBATIONS[n].kind == "geometric" for n in self.names)

    # -- θ handling --------------------------------------------------------------------------------------
    def check_theta(self, theta):
        """θ as ``(N, d)`` (a 1-D θ of length d is one row); ``ValueError`` on a wrong shape or non-finite values."""
        t = theta if isinstance(theta, torch.Tensor) else np.asarray(theta, dtype=np.float64)
        if t.ndim == 1 and t.shape[0] == self.dim:
            t = t[None, :]
        if t.ndim != 2 or t.shape[1] != self.dim:
            raise ValueError(f"theta must have shape (N, {self.dim}) for parameters {self.names}, got {tuple(t.shape)}")
        finite = bool(torch.isfinite(t).all()) if isinstance(t, torch.Tensor) else bool(np.isfinite(t).all())
        if not finite:
            raise ValueError(f"theta must be finite, got non-finite values for parameters {self.names}")
        for name, i in self._index.items():  # outside the box is allowed; outside the family's domain is not
            low = PERTURBATIONS[name].minimum
            col = t[:, i]
            if low > -np.inf and bool((col < low).any()):
                bad = float(col.min())
                raise ValueError(f"theta: {name} must be >= {low:g}, got {bad:g}")
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

    # -- images --------------------------------------------------------------------------------------------
    def images(self, image, theta, *, center=None):
        """Perturbed copies of one image, one per row of θ.

        Dispatches on the types: a NumPy image with a NumPy θ uses :meth:`images_numpy`; anything else
        :meth:`images_torch`.
        """
        if isinstance(image, np.ndarray) and not isinstance(theta, torch.Tensor):
            return self.images_numpy(image, theta, center=center)
        return self.images_torch(image, theta, center=center)

    __call__ = images

    def images_numpy(self, image: np.ndarray, theta, *, center=None) -> np.ndarray:
        """No-gradient path (OpenCV): ``image (H, W, C)`` uint8 or float in [0, 1] → ``(N, H, W, C)`` float32.

        ``center`` is the rotation centre in this image's pixels (the principal point); ``None`` = ``(W/2, H/2)``.
        """
        if not isinstance(image, np.ndarray) or image.ndim != 3:
            raise ValueError(f"images_numpy: image must be an (H, W, C) array, got {getattr(image, 'shape', image)!r}")
        t = self.check_theta(np.asarray(theta, dtype=np.float64))
        base = image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else image.astype(np.float32, copy=False)
        angles, factors = self.column(t, "roll_deg"), self.column(t, "contrast")
        out = np.empty((t.shape[0], *base.shape), dtype=np.float32)
        for k in range(t.shape[0]):
            if angles[k] == 0.0:
                out[k] = base
            else:
                rolled = roll_numpy(base, angles[k], center, out=out[k])
                if not np.shares_memory(rolled, out[k]):  # OpenCV could not write in place (e.g. 1 channel)
                    out[k] = rolled
            if factors[k] != 1.0:
                contrast_numpy(out[k], factors[k], out=out[k])
        return out

    def images_torch(self, image, theta, *, center=None) -> torch.Tensor:
        """Differentiable path: ``image (C, H, W)`` / ``(1, C, H, W)`` tensor (float in [0, 1] or uint8) or an
        ``(H, W, C)`` uint8 array → ``(N, C, H, W)``, differentiable w.r.t. θ (a tensor ``(N, d)``).

        Computed in the image's float dtype (float32 for uint8 input); θ may be float64 — the gradient flows back.
        """
        x = _as_chw_tensor(image)
        t = self.check_theta(theta if isinstance(theta, torch.Tensor) else torch.as_tensor(np.asarray(theta)))
        n = t.shape[0]
        if "roll_deg" in self._index:
            x = roll(x, self.column(t, "roll_deg"), center)
        if "contrast" in self._index:
            x = contrast(x, self.column(t, "contrast"))
        if x.shape[0] != n:
            x = x.expand(n, -1, -1, -1)
        return x

    # -- what the view sampler needs (vbl_robust.perturb.views.ViewSampler) ---------------------------------
    @property
    def has_photometric(self) -> bool:
        """True when some parameter changes pixel values (after the geometry)."""
        return any(PERTURBATIONS[n].kind == "photometric" for n in self.names)

    def source_coords(self, qu: torch.Tensor, qv: torch.Tensor, theta, center: torch.Tensor):
        """Inverse geometric map: perturbed-image OpenCV coordinates ``(B, …)`` → source coordinates (unreflected),
        for θ rows ``(B, d)``; the identity when no parameter is geometric."""
        if "roll_deg" not in self._index:
            return qu, qv
        return roll_source_coords(qu, qv, _column_tensor(self.column(theta, "roll_deg")), center)

    def photometric_stats(self, values: torch.Tensor) -> torch.Tensor:
        """``(B,)`` statistics the photometric families need, from samples ``(B, 3, n, n)`` of the geometrically
        perturbed frames (the grey mean of the contrast)."""
        return gray_mean(values)

    def photometric_torch(self, values: torch.Tensor, theta, stats: torch.Tensor) -> torch.Tensor:
        """The photometric families on pixel values ``(B, 3, …)`` of the geometrically perturbed frames."""
        if "contrast" in self._index:
            values = contrast_about(values, _column_tensor(self.column(theta, "contrast")), stats)
        return values

    # -- points --------------------------------------------------------------------------------------------
    def points(self, points, theta, *, center):
        """Move pixel points ``(P, 2)`` or ``(N, P, 2)`` as the image content moves: ``(N, P, 2)``.

        NumPy in, NumPy out; a tensor (points or θ) gives a tensor differentiable w.r.t. θ. ``center`` as in
        :meth:`images` (required: points carry no image size).
        """
        t = self.check_theta(theta)
        if "roll_deg" in self._index:
            return roll_points(points, self.column(t, "roll_deg"), center)
        n = t.shape[0]
        if isinstance(points, torch.Tensor) or isinstance(t, torch.Tensor):
            p = torch.as_tensor(points, dtype=t.dtype if isinstance(t, torch.Tensor) else torch.float64)
            return p[None].expand(n, -1, -1).clone() if p.ndim == 2 else p.clone()
        p = np.asarray(points, dtype=np.float64)
        return np.broadcast_to(p, (n, *p.shape[-2:])).copy()


def _column_tensor(col) -> torch.Tensor:
    return col if isinstance(col, torch.Tensor) else torch.as_tensor(np.asarray(col, dtype=np.float64))


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
