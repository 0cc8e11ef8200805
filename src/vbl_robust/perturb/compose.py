"""Apply the perturbations named by a :class:`~vbl_robust.space.ParameterBox` to one image, batched over θ.

Column ``i`` of a θ array ``(N, d)`` is the parameter ``box.names[i]`` in real units (see :mod:`vbl_robust.space`).
Known names are in :data:`PERTURBATIONS` (their conventions live in the family modules); a parameter absent from
the box keeps its identity value.

Order of application (the order of :data:`PERTURBATIONS`), following the light from the scene to the pixels:

1. **geometry** — the camera attitude ``roll_deg``, ``pitch_deg``, ``yaw_deg`` (one homography ``K R K⁻¹``,
   :mod:`.attitude`; roll alone is the rotation of :mod:`.geometric`);
2. **optics** — ``blur_px``, then ``motion_blur_px`` (convolutions of the perturbed frame, :mod:`.optical`; they
   commute);
3. **photometry** — ``haze`` (:mod:`.weather`; it commutes with the optics, so this is where the atmosphere
   acts), then ``contrast``, ``brightness``, ``gamma`` (:mod:`.photometric`, the camera's tone processing);
4. **noise** — ``noise_std`` (:mod:`.weather`), last, on the sensor's pixel grid.

The order matters where operations do not commute: the contrast's grey mean sees the reflected borders, the
blurs and the haze; the clamps of contrast, brightness and noise; gamma bends what came before it.

Units: angles in degrees; ``blur_px`` and ``motion_blur_px`` in pixels **of the sample's image** (the composer
scales them to a resized source with the :class:`~vbl_robust.perturb.PixelScale` it is given, so one θ means the
same physical blur for every detector resolution); ``brightness``, ``haze``, ``noise_std`` as fractions of full
scale; ``contrast`` and ``gamma`` dimensionless.

Camera: the attitude needs the pinhole ``K`` of the pixels it warps (``K=``, e.g.
:meth:`PixelScale.intrinsics <vbl_robust.perturb.PixelScale.intrinsics>` of the sample's ``K``); roll needs only
the principal point (``center=``, or ``K``'s).

Budget levels: every :class:`PerturbationSpec` carries a physically plausible ``default`` range (the CLI's
``--perturb NAME``) and five nested ``levels`` from mild to extreme, each with its justification (for
per-family experiments).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from vbl_robust.space import ParameterBox

from .attitude import attitude, attitude_numpy, attitude_points, attitude_source_coords
from .geometric import roll, roll_numpy, roll_points, roll_source_coords
from .optical import gaussian_blur, gaussian_blur_numpy, motion_blur, motion_blur_numpy
from .photometric import (
    LUMA_WEIGHTS,
    brightness,
    brightness_numpy,
    contrast,
    contrast_about,
    contrast_numpy,
    gamma,
    gamma_numpy,
    gray_mean,
)
from .resample import PixelScale
from .weather import (
    HAZE_AIRLIGHT,
    gaussian_noise,
    gaussian_noise_numpy,
    haze,
    haze_numpy,
    noise_pattern,
    noise_pattern_tensor,
)

__all__ = ["KINDS", "PERTURBATIONS", "Perturbation", "PerturbationSpec"]

#: What a family does: ``geometric`` moves pixels (and points); ``optical`` convolves the frame; ``photometric``
#: maps each pixel value; ``noise`` adds the fixed pattern on the frame's pixel grid.
KINDS = ("geometric", "optical", "photometric", "noise")


@dataclass(frozen=True)
class PerturbationSpec:
    """What a parameter name means.

    Attributes:
        name: the box's parameter name.
        kind: one of :data:`KINDS`.
        identity: the value that leaves the image unchanged.
        minimum, maximum: the family's domain (θ outside it is an error; the box may be anywhere inside).
        description: convention and unit, one line.
        unit: the unit (as :data:`vbl_robust.space.KNOWN_UNITS`).
        default: a physically plausible default range ``(lower, upper)``.
        levels: five nested ranges from mild to extreme (each contains the previous one and the identity).
        rationale: why these levels.
    """

    name: str
    kind: str
    identity: float
    minimum: float
    description: str
    maximum: float = np.inf
    unit: str = ""
    default: tuple[float, float] = (0.0, 0.0)
    levels: tuple[tuple[float, float], ...] = ()
    rationale: str = ""


def _sym(*half_widths: float) -> tuple[tuple[float, float], ...]:
    return tuple((-h, h) for h in half_widths)


def _upto(*highs: float) -> tuple[tuple[float, float], ...]:
    return tuple((0.0, h) for h in highs)


#: The parameter names a box may use, in the order they are applied (module docstring).
PERTURBATIONS: dict[str, PerturbationSpec] = {
    "roll_deg": PerturbationSpec(
        "roll_deg", "geometric", 0.0, -np.inf,
        "camera roll about the optical axis, degrees, positive = right wing down (image turns counter-clockwise)",
        unit="deg", default=(-15.0, 15.0), levels=_sym(2.0, 5.0, 10.0, 20.0, 30.0),
        rationale="a stabilised final approach banks a few degrees (±2–5°); gusts and corrections reach ±10°; "
                  "±20–30° is a turning approach (30° is the usual bank limit); the roll budgets of the paper",
    ),
    "pitch_deg": PerturbationSpec(
        "pitch_deg", "geometric", 0.0, -np.inf,
        "camera pitch about its left axis, degrees, positive = nose up (scene moves down in the image)",
        unit="deg", default=(-5.0, 5.0), levels=_sym(1.0, 2.0, 5.0, 10.0, 15.0),
        rationale="±1° is an attitude-estimate or camera-mount error; ±2° a glide-path deviation; ±5° turbulence "
                  "and flare; ±10–15° go-around or upset attitudes (the runway leaves a 60° FOV beyond ~±20°)",
    ),
    "yaw_deg": PerturbationSpec(
        "yaw_deg", "geometric", 0.0, -np.inf,
        "camera yaw about its up axis, degrees, positive = nose right (scene moves left in the image)",
        unit="deg", default=(-5.0, 5.0), levels=_sym(1.0, 2.0, 5.0, 10.0, 20.0),
        rationale="±1–2° is a heading-estimate or mount error; ±5–10° the crab angle of a crosswind approach; "
                  "±20° an extreme crab (the LARD envelopes sample ±24° of heading offset)",
    ),
    "blur_px": PerturbationSpec(
        "blur_px", "optical", 0.0, 0.0,
        "Gaussian blur, standard deviation in pixels of the sample's image (defocus, turbulence, dirty lens)",
        unit="px", default=(0.0, 2.0), levels=_upto(0.5, 1.0, 2.0, 4.0, 8.0),
        rationale="σ ≤ 0.5 px is a sharp lens; 1–2 px mild defocus or compression softening; 4 px a misted or "
                  "defocused lens; 8 px (0.5° at LARD's 1024 px / 60°) a severely degraded image",
    ),
    "motion_blur_px": PerturbationSpec(
        "motion_blur_px", "optical", 0.0, 0.0,
        "horizontal linear motion blur, length in pixels of the sample's image, centred (yaw rate x exposure)",
        unit="px", default=(0.0, 8.0), levels=_upto(2.0, 4.0, 8.0, 16.0, 32.0),
        rationale="angular rate x exposure x focal length: 5°/s for 10 ms at 887 px/rad is 0.8 px; turbulence "
                  "at 20°/s for 20 ms gives 6 px; 16–32 px are long exposures in low light with strong turbulence",
    ),
    "haze": PerturbationSpec(
        "haze", "photometric", 0.0, 0.0,
        "uniform haze, fraction of airlight A = 0.8 blended in (x' = (1 - h) x + h A), 0 = clear",
        maximum=1.0, unit="fraction", default=(0.0, 0.4), levels=_upto(0.1, 0.2, 0.4, 0.6, 0.8),
        rationale="Koschmieder h = 1 - exp(-3.912 d / V) at d = 2 km: visibility V = 75, 35, 15, 8.5 and 4.9 km; "
                  "0.8 is about the visibility minimum of a visual approach",
    ),
    "contrast": PerturbationSpec(
        "contrast", "photometric", 1.0, 0.0, "contrast factor (torchvision definition), 1 = unchanged",
        unit="factor", default=(0.7, 1.4), levels=((0.9, 1.1), (0.8, 1.25), (0.7, 1.4), (0.5, 2.0), (0.4, 2.5)),
        rationale="multiplicatively symmetric about 1 (0.8 ≈ 1/1.25); the paper's 2-D boxes; 0.4–2.5 washes the "
                  "image out or saturates most of it",
    ),
    "brightness": PerturbationSpec(
        "brightness", "photometric", 0.0, -np.inf,
        "additive brightness offset, fraction of full scale (0.1 = +25.5 grey levels), clamped to [0, 1]",
        unit="full scale", default=(-0.2, 0.2), levels=_sym(0.05, 0.1, 0.2, 0.3, 0.5),
        rationale="±0.05 is auto-exposure jitter; ±0.1–0.2 an exposure error of about ±1/3–2/3 stop at mid grey; "
                  "±0.3–0.5 sun glare or a failed exposure control",
    ),
    "gamma": PerturbationSpec(
        "gamma", "photometric", 1.0, 0.0,
        "gamma exponent x' = x ** gamma, 1 = unchanged (< 1 brightens the shadows)",
        unit="exponent", default=(0.67, 1.5), levels=((0.9, 1.1), (0.8, 1.25), (0.67, 1.5), (0.5, 2.0), (0.4, 2.5)),
        rationale="multiplicatively symmetric about 1; 0.8–1.25 spans tone curves of camera profiles, 0.5–2 a "
                  "wrong encoding assumption (linear vs sRGB is about 2.2)",
    ),
    "noise_std": PerturbationSpec(
        "noise_std", "noise", 0.0, 0.0,
        "additive Gaussian noise, standard deviation in fraction of full scale, fixed seeded pattern",
        unit="full scale", default=(0.0, 0.05), levels=_upto(0.01, 0.02, 0.05, 0.1, 0.2),
        rationale="0.01 (2.5 grey levels) is a daylight sensor; 0.02–0.05 dusk or high gain; 0.1–0.2 night "
                  "imaging at maximum gain",
    ),
}

#: The families that move pixels: one homography. Roll alone keeps the rotation of :mod:`.geometric`.
ATTITUDE = ("roll_deg", "pitch_deg", "yaw_deg")


def _known() -> str:
    return ", ".join(PERTURBATIONS)


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
    * ``scale`` — the :class:`~vbl_robust.perturb.PixelScale` from the sample's pixels to the image's (blur
      lengths and the noise grid are in the sample's pixels); ``None`` = the image is the sample's.
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
            for name, lo, hi in zip(box.names, box.lower, box.upper, strict=True):
                spec = PERTURBATIONS[name]
                if lo < spec.minimum:
                    raise ValueError(f"Perturbation: lower bound of {name!r} must be >= {spec.minimum}, got {lo}")
                if hi > spec.maximum:
                    raise ValueError(f"Perturbation: upper bound of {name!r} must be <= {spec.maximum}, got {hi}")
        self.names = names
        self._index = {n: i for i, n in enumerate(names)}

    def __repr__(self) -> str:
        return f"Perturbation({list(self.names)})"

    @property
    def dim(self) -> int:
        return len(self.names)

    def has(self, name: str) -> bool:
        """True when the box has the parameter ``name``."""
        return name in self._index

    def _kinds(self) -> set[str]:
        return {PERTURBATIONS[n].kind for n in self.names}

    @property
    def is_geometric(self) -> bool:
        """True when some parameter moves pixels (keypoints must then be moved too)."""
        return "geometric" in self._kinds()

    @property
    def uses_homography(self) -> bool:
        """True when the geometry is the full attitude homography (``pitch_deg`` or ``yaw_deg`` in the box);
        a roll-only box keeps the rotation of :mod:`.geometric` bit for bit."""
        return self.has("pitch_deg") or self.has("yaw_deg")

    @property
    def needs_frame(self) -> bool:
        """True when some family acts on whole perturbed frames (``optical`` convolutions, the ``noise`` pattern
        of the sensor grid): views must then be cut from rendered frames (see
        :class:`~vbl_robust.perturb.ViewSampler`)."""
        return bool(self._kinds() & {"optical", "noise"})

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
        elif self.uses_homography:
            wanted = [n for n in ("pitch_deg", "yaw_deg") if self.has(n)]
            raise ValueError(f"Perturbation: {' and '.join(wanted)} need the camera intrinsics: pass K (3, 3) in "
                             "the image's pixels")
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

    def images_numpy(self, image: np.ndarray, theta, *, center=None, K=None, scale=None) -> np.ndarray:
        """No-gradient path (OpenCV): ``image (H, W, C)`` uint8 or float in [0, 1] → ``(N, H, W, C)`` float32.

        Camera arguments: see the class docstring.
        """
        if not isinstance(image, np.ndarray) or image.ndim != 3:
            raise ValueError(f"images_numpy: image must be an (H, W, C) array, got {getattr(image, 'shape', image)!r}")
        t = self.check_theta(np.asarray(theta, dtype=np.float64))
        h, w = image.shape[:2]
        center, K = self._camera(center, K)
        sc = self._scale(scale)
        base = image.astype(np.float32) / 255.0 if image.dtype == np.uint8 else image.astype(np.float32, copy=False)
        col = {name: self.column(t, name) for name in PERTURBATIONS}
        homography = self.uses_homography
        pattern = (noise_pattern(h, w, base.shape[2], base_size=sc.original_size(w, h))
                   if self.has("noise_std") else None)
        out = np.empty((t.shape[0], *base.shape), dtype=np.float32)
        for k in range(t.shape[0]):
            angles = [col[n][k] for n in ATTITUDE]
            if not any(angles):
                out[k] = base
            else:
                warped = (attitude_numpy(base, *angles, K, out=out[k]) if homography
                          else roll_numpy(base, angles[0], center, out=out[k]))
                if not np.shares_memory(warped, out[k]):  # OpenCV could not write in place (e.g. 1 channel)
                    out[k] = warped
            frame = out[k]
            if col["blur_px"][k] > 0.0:
                gaussian_blur_numpy(frame, col["blur_px"][k] * sc.sx, col["blur_px"][k] * sc.sy, out=frame)
            if col["motion_blur_px"][k] > 0.0:
                motion_blur_numpy(frame, col["motion_blur_px"][k] * sc.sx, out=frame)
            if col["haze"][k] != 0.0:
                haze_numpy(frame, col["haze"][k], out=frame)
            if col["contrast"][k] != 1.0:
                contrast_numpy(frame, col["contrast"][k], out=frame)
            if col["brightness"][k] != 0.0:
                brightness_numpy(frame, col["brightness"][k], out=frame)
            if col["gamma"][k] != 1.0:
                gamma_numpy(frame, col["gamma"][k], out=frame)
            if col["noise_std"][k] != 0.0:
                gaussian_noise_numpy(frame, col["noise_std"][k], pattern, out=frame)
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
        h, w = x.shape[-2:]
        center, K = self._camera(center, K)
        sc = self._scale(scale)
        if self.uses_homography:
            x = attitude(x, *(self.column(t, a) for a in ATTITUDE), K)
        elif self.has("roll_deg"):
            x = roll(x, self.column(t, "roll_deg"), center)
        if self.has("blur_px"):
            s = self.column(t, "blur_px")
            x = gaussian_blur(x, torch.stack([s * sc.sx, s * sc.sy], dim=-1))
        if self.has("motion_blur_px"):
            x = motion_blur(x, self.column(t, "motion_blur_px") * sc.sx)
        x = self._photometric(x, t, None)
        if self.has("noise_std"):
            pattern = noise_pattern_tensor(h, w, x.shape[1], base_size=sc.original_size(w, h)).to(x.device)
            x = gaussian_noise(x, self.column(t, "noise_std"), pattern)
        if x.shape[0] != n:
            x = x.expand(n, -1, -1, -1)
        return x

    def _photometric(self, values: torch.Tensor, theta, stats):
        """Haze, contrast, brightness and gamma, in that order; ``stats`` = the grey means of the frames before
        them (None: compute them from ``values``, which are then whole frames)."""
        if self.has("haze"):
            amount = _column_tensor(self.column(theta, "haze"), values)
            values = haze(values, amount)
        if self.has("contrast"):
            factor = _column_tensor(self.column(theta, "contrast"), values)
            if stats is None:
                values = contrast(values, factor)
            else:
                if self.has("haze"):  # the grey mean of the hazed frame, exactly (the blend is linear)
                    grey = HAZE_AIRLIGHT * (sum(LUMA_WEIGHTS) if values.shape[1] == 3 else 1.0)
                    a = amount.to(stats.dtype)
                    stats = (1.0 - a) * stats + a * grey
                values = contrast_about(values, factor, stats)
        if self.has("brightness"):
            values = brightness(values, _column_tensor(self.column(theta, "brightness"), values))
        if self.has("gamma"):
            values = gamma(values, _column_tensor(self.column(theta, "gamma"), values))
        return values

    # -- what the view sampler needs (vbl_robust.perturb.views.ViewSampler) ---------------------------------
    @property
    def has_photometric(self) -> bool:
        """True when some parameter changes pixel values pointwise (after the geometry)."""
        return "photometric" in self._kinds()

    @property
    def needs_stats(self) -> bool:
        """True when a photometric family needs statistics of the whole frame (the contrast's grey mean)."""
        return self.has("contrast")

    def source_coords(self, qu: torch.Tensor, qv: torch.Tensor, theta, center: torch.Tensor, K=None):
        """Inverse geometric map: perturbed-image OpenCV coordinates ``(B, …)`` → source coordinates (unreflected),
        for θ rows ``(B, d)``; the identity when no parameter is geometric. ``K`` (3, 3): required by the attitude
        homography (``pitch_deg``/``yaw_deg``)."""
        if self.uses_homography:
            if K is None:
                raise ValueError("Perturbation.source_coords: pitch_deg/yaw_deg need the intrinsics K")
            cols = [_column_tensor(self.column(theta, a), qu) for a in ATTITUDE]
            return attitude_source_coords(qu, qv, *cols, K)
        if "roll_deg" not in self._index:
            return qu, qv
        return roll_source_coords(qu, qv, _column_tensor(self.column(theta, "roll_deg"), qu), center)

    def photometric_stats(self, values: torch.Tensor) -> torch.Tensor:
        """``(B,)`` statistics the photometric families need, from samples ``(B, 3, n, n)`` of the geometrically
        perturbed frames (the grey mean of the contrast)."""
        return gray_mean(values)

    def photometric_torch(self, values: torch.Tensor, theta, stats: torch.Tensor | None) -> torch.Tensor:
        """The pointwise photometric families (haze, contrast, brightness, gamma) on pixel values ``(B, 3, …)`` of
        the geometrically perturbed frames; ``stats`` from :meth:`photometric_stats` (needed by the contrast)."""
        if self.has("contrast") and stats is None:
            raise ValueError("Perturbation.photometric_torch: the contrast needs the frames' grey means (stats)")
        return self._photometric(values, theta, stats)

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
            if self.uses_homography:
                return attitude_points(points, *(self.column(t, a) for a in ATTITUDE), K)
            if center is None:
                raise ValueError("Perturbation.points: roll_deg needs the rotation centre (center=) or K")
            return roll_points(points, self.column(t, "roll_deg"), center)
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
