"""Perturbations T(x; θ): camera attitude, blur, photometry, haze and sensor noise, each with its 2D point transform.

Functions take batched tensors and are differentiable w.r.t. their parameters (kornia style, with thin
``nn.Module`` wrappers); OpenCV/NumPy twins serve the no-gradient path. :class:`Perturbation` ties them to the
parameter names of a :class:`~vbl_robust.space.ParameterBox` (the registry :data:`PERTURBATIONS`, in the order
of application: geometry, optics, photometry, noise — see :mod:`.compose`). Conventions live where the families
do: :mod:`.geometric` (roll: centre, sign, padding), :mod:`.attitude` (roll, pitch, yaw as ``K R K⁻¹``),
:mod:`.optical` (Gaussian and motion blur), :mod:`.photometric` (contrast, brightness, gamma), :mod:`.weather`
(haze and its airlight, the seeded noise pattern) and :mod:`.resample` (resizing, scaled intrinsics).

:class:`ViewSampler` (:mod:`.views`) is the boundary to the detectors: the views of ``T(x; θ)`` that a detector
asks for (the letterboxed frame, crops), sampled from the unperturbed image, and points moved both ways.
"""

from .attitude import Attitude, attitude, attitude_homography, attitude_numpy, attitude_points
from .compose import KINDS, PERTURBATIONS, Perturbation, PerturbationSpec
from .geometric import Roll, default_center, roll, roll_matrix, roll_numpy, roll_points
from .optical import (
    GaussianBlur,
    MotionBlur,
    gaussian_blur,
    gaussian_blur_numpy,
    motion_blur,
    motion_blur_numpy,
)
from .photometric import (
    LUMA_WEIGHTS,
    Brightness,
    Contrast,
    Gamma,
    brightness,
    brightness_numpy,
    contrast,
    contrast_numpy,
    gamma,
    gamma_numpy,
)
from .resample import PixelScale, resize_image
from .views import ViewSampler
from .weather import (
    HAZE_AIRLIGHT,
    NOISE_SEED,
    GaussianNoise,
    Haze,
    gaussian_noise,
    gaussian_noise_numpy,
    haze,
    haze_numpy,
    noise_pattern,
)

__all__ = [
    "HAZE_AIRLIGHT",
    "KINDS",
    "LUMA_WEIGHTS",
    "NOISE_SEED",
    "PERTURBATIONS",
    "Attitude",
    "Brightness",
    "Contrast",
    "Gamma",
    "GaussianBlur",
    "GaussianNoise",
    "Haze",
    "MotionBlur",
    "Perturbation",
    "PerturbationSpec",
    "PixelScale",
    "Roll",
    "ViewSampler",
    "attitude",
    "attitude_homography",
    "attitude_numpy",
    "attitude_points",
    "brightness",
    "brightness_numpy",
    "contrast",
    "contrast_numpy",
    "default_center",
    "gamma",
    "gamma_numpy",
    "gaussian_blur",
    "gaussian_blur_numpy",
    "gaussian_noise",
    "gaussian_noise_numpy",
    "haze",
    "haze_numpy",
    "motion_blur",
    "motion_blur_numpy",
    "noise_pattern",
    "resize_image",
    "roll",
    "roll_matrix",
    "roll_numpy",
    "roll_points",
]
