"""Perturbations T(x; θ): camera attitude, blur, photometry, haze and sensor noise, each with its 2D point transform.

Functions take batched tensors and are differentiable w.r.t. their parameters (kornia style, with thin
``nn.Module`` wrappers); OpenCV/NumPy twins serve the no-gradient path. :class:`Perturbation` ties them to the
parameter names of a :class:`~vbl_robust.space.ParameterBox` (the registry :data:`PERTURBATIONS`, in the order
of application: geometry, optics, photometry, noise — see :mod:`.registry`; each family's maps are one
:class:`~vbl_robust.perturb.family.Family`). Conventions live where the families
do: :mod:`.geometric` (roll: centre, sign, padding), :mod:`.rotation` (roll, pitch, yaw as ``K R K⁻¹``),
:mod:`.optical` (Gaussian and motion blur), :mod:`.photometric` (contrast, brightness, gamma), :mod:`.weather`
(haze and its airlight, the seeded noise pattern) and :mod:`.resample` (resizing, scaled intrinsics).

:class:`ViewSampler` (:mod:`.views`) is the boundary to the detectors: the views of ``T(x; θ)`` that a detector
asks for (the letterboxed frame, crops), sampled from the unperturbed image, and points moved both ways.

Names are resolved lazily: reading the registry (the command line's help does) imports no torch.
"""

from __future__ import annotations

from vbl_robust.lazy import lazy_names

#: public name -> the submodule that defines it
_LAZY: dict[str, str] = {
    "Attitude": ".rotation",
    "attitude": ".rotation",
    "attitude_homography": ".rotation",
    "attitude_numpy": ".rotation",
    "attitude_points": ".rotation",
    "KINDS": ".registry",
    "PERTURBATIONS": ".registry",
    "PerturbationSpec": ".registry",
    "Perturbation": ".compose",
    "Roll": ".geometric",
    "roll": ".geometric",
    "roll_numpy": ".geometric",
    "roll_points": ".geometric",
    "GaussianBlur": ".optical",
    "MotionBlur": ".optical",
    "gaussian_blur": ".optical",
    "gaussian_blur_numpy": ".optical",
    "motion_blur": ".optical",
    "motion_blur_numpy": ".optical",
    "Brightness": ".photometric",
    "Contrast": ".photometric",
    "Gamma": ".photometric",
    "brightness": ".photometric",
    "brightness_numpy": ".photometric",
    "contrast": ".photometric",
    "contrast_numpy": ".photometric",
    "gamma": ".photometric",
    "gamma_numpy": ".photometric",
    "PixelScale": ".resample",
    "resize_image": ".resample",
    "ViewSampler": ".views",
    "HAZE_AIRLIGHT": ".weather",
    "NOISE_SEED": ".weather",
    "GaussianNoise": ".weather",
    "Haze": ".weather",
    "gaussian_noise": ".weather",
    "gaussian_noise_numpy": ".weather",
    "haze": ".weather",
    "haze_numpy": ".weather",
    "noise_pattern": ".weather",
}

__all__ = sorted(_LAZY)  # every public name is lazy: listed once, in _LAZY


__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals(), __all__)
