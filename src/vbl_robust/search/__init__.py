"""Searches that maximise a batched function over a :class:`~vbl_robust.space.ParameterBox`.

They know nothing of images: ``f`` maps ``(n, d)`` real-unit points to ``(n,)`` values, or to
:class:`~.evaluations.Evaluations` (values and a failure reason per point: a failed evaluation is a recorded
state, counted per reason in :attr:`~.result.SearchResult.failures`). Every method has the same ask/tell
interface (:class:`~.base.Optimizer`) and is registered by name in :data:`METHODS`: ``"georobust"``,
``"direct"``, ``"direct-l"`` (the DIRECT family), ``"georobust-a"`` (GeoRobust whose division follows where the
objective varies, :mod:`~vbl_robust.search.adaptive`), ``"georobust-av"`` (the same, plus the box's vertices in
its first batch), ``"random"``, ``"sobol"``, ``"apgd"`` (needs a torch-differentiable ``f``) and ``"grid"``
(ground truth in low dimension).

Every evaluation is stamped with its completion time; :func:`~.anytime.at_budget` reads a result at any smaller
time or evaluation budget off those stamps (one run of an *anytime* method answers every smaller budget, see
:mod:`~vbl_robust.search.anytime`).

>>> import numpy as np
>>> from vbl_robust.space import ParameterBox
>>> box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
>>> r = maximize(lambda x: -np.abs(x[:, 0] - 5) - np.abs(x[:, 1] - 1), box, "direct", max_evals=300)
>>> r.status.value, r.nfev <= 300, bool(abs(r.x[0] - 5) < 0.1)
('budget_exhausted', True, True)
"""

from .api import METHODS, maximize
from .direct import GeoRobust

__all__ = ["METHODS", "GeoRobust", "maximize"]
