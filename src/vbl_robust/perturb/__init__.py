"""Perturbations T(x; θ): camera roll about the principal point and contrast, each with its 2D point transform.

Functions take batched tensors and are differentiable w.r.t. their parameters (kornia style, with thin
``nn.Module`` wrappers); OpenCV/NumPy twins serve the no-gradient path. :class:`Perturbation` ties them to the
parameter names of a :class:`~vbl_robust.space.ParameterBox`. Conventions live in :mod:`.geometric`
(roll: centre, sign, padding), :mod:`.photometric` (contrast) and :mod:`.resample` (resizing).

:class:`ViewSampler` (:mod:`.views`) is the boundary to the detectors: the views of ``T(x; θ)`` that a detector
asks for (the letterboxed frame, crops), sampled from the unperturbed image, and points moved both ways.
"""

from .compose import PERTURBATIONS, Perturbation, PerturbationSpec
from .geometric import Roll, default_center, roll, roll_matrix, roll_numpy, roll_points
from .photometric import LUMA_WEIGHTS, Contrast, contrast, contrast_numpy
from .resample import PixelScale, resize_image
from .views import ViewSampler

__all__ = [
    "LUMA_WEIGHTS",
    "PERTURBATIONS",
    "Contrast",
    "Perturbation",
    "PerturbationSpec",
    "PixelScale",
    "Roll",
    "ViewSampler",
    "contrast",
    "contrast_numpy",
    "default_center",
    "resize_image",
    "roll",
    "roll_matrix",
    "roll_numpy",
    "roll_points",
]
