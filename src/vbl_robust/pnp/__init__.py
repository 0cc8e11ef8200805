"""PnP on the four runway corners: OpenCV solvers with failure flags, and a differentiable layer.

See :mod:`.solvers` for conventions (OpenCV pixels, world → camera ``rvec``/``tvec``, ``C = −Rᵀt``) and
``notes/pnp.md`` for the facts behind the choice of solvers.
"""

from .solvers import SOLVERS, PnPResult, solve

__all__ = ["SOLVERS", "PnPResult", "solve"]
