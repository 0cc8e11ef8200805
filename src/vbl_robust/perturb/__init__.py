"""Perturbations T(x; θ): camera attitude, blur, photometry, haze and sensor noise, each with its 2D point transform.

Functions take batched tensors and are differentiable w.r.t. their parameters (kornia style, with thin
``nn.Module`` wrappers); OpenCV/NumPy twins serve the no-gradient path. :class:`~.compose.Perturbation` ties
them to the parameter names of a :class:`~vbl_robust.space.ParameterBox` (the registry
:data:`~.registry.PERTURBATIONS`, in the order of application: geometry, optics, photometry, noise — see
:mod:`.registry`; each family's maps are one :class:`~vbl_robust.perturb.family.Family`). Conventions live where
the families do: :mod:`.geometric` (roll: centre, sign, padding), :mod:`.rotation` (roll, pitch, yaw as
``K R K⁻¹``), :mod:`.optical` (Gaussian and motion blur), :mod:`.photometric` (contrast, brightness, gamma),
:mod:`.weather` (haze and its airlight, the seeded noise pattern) and :mod:`.resample` (resizing, scaled
intrinsics).

:class:`~.views.ViewSampler` (:mod:`.views`) is the boundary to the detectors: the views of ``T(x; θ)`` that a
detector asks for (the letterboxed frame, crops), sampled from the unperturbed image, and points moved both ways.

The package exports no names: each is imported from its module; reading the registry (:mod:`.registry`, as the
command line's help does) imports no torch.
"""
