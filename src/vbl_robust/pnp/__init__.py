"""PnP on the four runway corners: OpenCV solvers with failure flags, and a differentiable layer.

See :mod:`.solvers` for conventions (OpenCV pixels, world → camera ``rvec``/``tvec``, ``C = −Rᵀt``) and the
facts behind the choice of solvers, :mod:`.differentiable` for why the differentiable layer is hand-written;
:mod:`.ippe` solves both IPPE poses of a batch in closed form, :mod:`.refine` refines poses (batched
Levenberg–Marquardt).
"""
