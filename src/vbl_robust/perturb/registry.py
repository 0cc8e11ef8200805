"""The perturbation registry: what each parameter name of a box means, and where its family's maps live.

One entry per parameter, in the order the families are applied — following the light from the scene to the pixels:

1. **geometry** — the camera attitude ``roll_deg``, ``pitch_deg``, ``yaw_deg`` (one homography ``K R K⁻¹``,
   :mod:`.rotation`; roll alone is the rotation of :mod:`.geometric`);
2. **optics** — ``blur_px``, then ``motion_blur_px`` (convolutions of the perturbed frame, :mod:`.optical`; they
   commute);
3. **photometry** — ``haze`` (:mod:`.weather`; it commutes with the optics, so this is where the atmosphere
   acts), then ``contrast``, ``brightness``, ``gamma`` (:mod:`.photometric`, the camera's tone processing);
4. **noise** — ``noise_std`` (:mod:`.weather`), last, on the sensor's pixel grid.

The order matters where operations do not commute: the contrast's grey mean sees the reflected borders, the
blurs and the haze; the clamps of contrast, brightness and noise; gamma bends what came before it.

A new family is one module holding a :class:`~vbl_robust.perturb.family.Family` and one entry here;
:class:`~vbl_robust.perturb.compose.Perturbation`, the view sampler, the training augmentation and the command line's help
read this table and nothing else. This module imports no torch (the command line's help reads it).

Budget levels: every :class:`PerturbationSpec` carries a physically plausible ``default`` range (the CLI's
``--perturb NAME``) and five nested ``levels`` from mild to extreme, each with its justification (for
per-family experiments).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .family import Family

__all__ = ["KINDS", "PERTURBATIONS", "FamilyKind", "PerturbationSpec", "family_of", "known"]

class FamilyKind(StrEnum):
    """What a family does: ``GEOMETRIC`` moves pixels (and points); ``OPTICAL`` convolves the frame;
    ``PHOTOMETRIC`` maps each pixel value; ``NOISE`` adds the fixed pattern on the frame's pixel grid."""

    GEOMETRIC = "geometric"
    OPTICAL = "optical"
    PHOTOMETRIC = "photometric"
    NOISE = "noise"


#: The values of :class:`FamilyKind`, in order.
KINDS = tuple(k.value for k in FamilyKind)


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
        family: where the family's maps live, ``"module:NAME"``: a module path as ``import`` takes it, relative
            to :mod:`vbl_robust.perturb` when it starts with a dot (``".optical:GAUSSIAN_BLUR"``) (a :class:`~vbl_robust.perturb.family.Family`; several
            parameters may share one, as roll, pitch and yaw).
        multiplicative: ranges are symmetric in ratio about the identity (sampled log-uniformly in training).
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
    family: str = ""
    multiplicative: bool = False


def _sym(*half_widths: float) -> tuple[tuple[float, float], ...]:
    return tuple((-h, h) for h in half_widths)


def _upto(*highs: float) -> tuple[tuple[float, float], ...]:
    return tuple((0.0, h) for h in highs)


#: The parameter names a box may use, in the order they are applied (module docstring).
PERTURBATIONS: dict[str, PerturbationSpec] = {
    "roll_deg": PerturbationSpec(
        "roll_deg", "geometric", 0.0, -180.0,
        "camera roll about the optical axis, degrees, positive = right wing down (image turns counter-clockwise)",
        maximum=180.0, unit="deg", default=(-15.0, 15.0), levels=_sym(2.0, 5.0, 10.0, 20.0, 30.0),
        rationale="a stabilised final approach banks a few degrees (±2–5°); gusts and corrections reach ±10°; "
                  "±20–30° is a turning approach (30° is the usual bank limit); the roll budgets of the paper",
        family=".rotation:CAMERA_ATTITUDE",
    ),
    "pitch_deg": PerturbationSpec(
        "pitch_deg", "geometric", 0.0, -180.0,
        "camera pitch about its left axis, degrees, positive = nose up (scene moves down in the image)",
        maximum=180.0, unit="deg", default=(-5.0, 5.0), levels=_sym(1.0, 2.0, 5.0, 10.0, 15.0),
        rationale="±1° is an attitude-estimate or camera-mount error; ±2° a glide-path deviation; ±5° turbulence "
                  "and flare; ±10–15° go-around or upset attitudes (the runway leaves a 60° FOV beyond ~±20°)",
        family=".rotation:CAMERA_ATTITUDE",
    ),
    "yaw_deg": PerturbationSpec(
        "yaw_deg", "geometric", 0.0, -180.0,
        "camera yaw about its up axis, degrees, positive = nose right (scene moves left in the image)",
        maximum=180.0, unit="deg", default=(-5.0, 5.0), levels=_sym(1.0, 2.0, 5.0, 10.0, 20.0),
        rationale="±1–2° is a heading-estimate or mount error; ±5–10° the crab angle of a crosswind approach; "
                  "±20° an extreme crab (the LARD envelopes sample ±24° of heading offset)",
        family=".rotation:CAMERA_ATTITUDE",
    ),
    "blur_px": PerturbationSpec(
        "blur_px", "optical", 0.0, 0.0,
        "Gaussian blur, standard deviation in pixels of the sample's image (defocus, turbulence, dirty lens)",
        unit="px", default=(0.0, 2.0), levels=_upto(0.5, 1.0, 2.0, 4.0, 8.0),
        rationale="σ ≤ 0.5 px is a sharp lens; 1–2 px mild defocus or compression softening; 4 px a misted or "
                  "defocused lens; 8 px (0.5° at LARD's 1024 px / 60°) a severely degraded image",
        family=".optical:GAUSSIAN_BLUR",
    ),
    "motion_blur_px": PerturbationSpec(
        "motion_blur_px", "optical", 0.0, 0.0,
        "horizontal linear motion blur, length in pixels of the sample's image, centred (yaw rate x exposure)",
        unit="px", default=(0.0, 8.0), levels=_upto(2.0, 4.0, 8.0, 16.0, 32.0),
        rationale="angular rate x exposure x focal length: 5°/s for 10 ms at 887 px/rad is 0.8 px; turbulence "
                  "at 20°/s for 20 ms gives 6 px; 16–32 px are long exposures in low light with strong turbulence",
        family=".optical:MOTION_BLUR",
    ),
    "haze": PerturbationSpec(
        "haze", "photometric", 0.0, 0.0,
        "uniform haze, fraction of airlight A = 0.8 blended in (x' = (1 - h) x + h A), 0 = clear",
        maximum=1.0, unit="fraction", default=(0.0, 0.4), levels=_upto(0.1, 0.2, 0.4, 0.6, 0.8),
        rationale="Koschmieder h = 1 - exp(-3.912 d / V) at d = 2 km: visibility V = 75, 35, 15, 8.5 and 4.9 km; "
                  "0.8 is about the visibility minimum of a visual approach",
        family=".weather:HAZE",
    ),
    "contrast": PerturbationSpec(
        "contrast", "photometric", 1.0, 0.0, "contrast factor (torchvision definition), 1 = unchanged",
        unit="factor", default=(0.7, 1.4), levels=((0.9, 1.1), (0.8, 1.25), (0.7, 1.4), (0.5, 2.0), (0.4, 2.5)),
        rationale="multiplicatively symmetric about 1 (0.8 ≈ 1/1.25); the paper's 2-D boxes; 0.4–2.5 washes the "
                  "image out or saturates most of it",
        family=".photometric:CONTRAST", multiplicative=True,
    ),
    "brightness": PerturbationSpec(
        "brightness", "photometric", 0.0, -np.inf,
        "additive brightness offset, fraction of full scale (0.1 = +25.5 grey levels), clamped to [0, 1]",
        unit="full scale", default=(-0.2, 0.2), levels=_sym(0.05, 0.1, 0.2, 0.3, 0.5),
        rationale="±0.05 is auto-exposure jitter; ±0.1–0.2 an exposure error of about ±1/3–2/3 stop at mid grey; "
                  "±0.3–0.5 sun glare or a failed exposure control",
        family=".photometric:BRIGHTNESS",
    ),
    "gamma": PerturbationSpec(
        "gamma", "photometric", 1.0, 0.0,
        "gamma exponent x' = x ** gamma, 1 = unchanged (< 1 brightens the shadows)",
        unit="exponent", default=(0.67, 1.5), levels=((0.9, 1.1), (0.8, 1.25), (0.67, 1.5), (0.5, 2.0), (0.4, 2.5)),
        rationale="multiplicatively symmetric about 1; 0.8–1.25 spans tone curves of camera profiles, 0.5–2 a "
                  "wrong encoding assumption (linear vs sRGB is about 2.2)",
        family=".photometric:GAMMA", multiplicative=True,
    ),
    "noise_std": PerturbationSpec(
        "noise_std", "noise", 0.0, 0.0,
        "additive Gaussian noise, standard deviation in fraction of full scale, fixed seeded pattern",
        unit="full scale", default=(0.0, 0.05), levels=_upto(0.01, 0.02, 0.05, 0.1, 0.2),
        rationale="0.01 (2.5 grey levels) is a daylight sensor; 0.02–0.05 dusk or high gain; 0.1–0.2 night "
                  "imaging at maximum gain",
        family=".weather:SENSOR_NOISE",
    ),
}


def known() -> str:
    """The registered names, comma-separated (for error messages and help)."""
    return ", ".join(PERTURBATIONS)


def family_of(name: str) -> Family:
    """The :class:`~vbl_robust.perturb.family.Family` of the registered parameter ``name`` (imported on first
    use)."""
    module, attr = PERTURBATIONS[name].family.split(":")
    return getattr(importlib.import_module(module, package=__package__), attr)
