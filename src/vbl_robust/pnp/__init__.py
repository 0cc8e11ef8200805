"""PnP on the four runway corners: OpenCV solvers with failure flags, and a differentiable layer.

See :mod:`.solvers` for conventions (OpenCV pixels, world → camera ``rvec``/``tvec``, ``C = −Rᵀt``) and the
facts behind the choice of solvers, :mod:`.differentiable` for why the differentiable layer is hand-written.
"""

from .differentiable import GRAD_MODES, PnPPosition, pnp_position_torch, position_sigma
from .solvers import SOLVERS, PnPResult, solve

__all__ = ["GRAD_MODES", "SOLVERS", "PnPPosition", "PnPResult", "pnp_position_torch", "position_sigma", "solve"]
