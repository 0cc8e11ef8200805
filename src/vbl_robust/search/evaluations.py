"""What an objective may return for a batch: plain values, or :class:`Evaluations` (values + failure reasons).

A *failed* evaluation is a recorded state, not an exception. An objective that knows why a point failed (no
detection, PnP failure, …) returns ``Evaluations(values, reasons)``: the search uses ``values`` exactly as it
would a plain array (a failed point usually carries a finite penalty, e.g. 5000 m, and is searched like any
other), and the result counts the failures per reason (:attr:`SearchResult.failures`).

Conventions: ``reasons[i] == ""`` is a success; codes are free strings (the pipeline's are
:data:`vbl_robust.constants.FAILURE_REASONS`). A NaN/±inf value told without a reason is recorded with
:data:`NON_FINITE`, so a plain array return keeps working (NaN/inf = failed, as always).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Reason recorded for a NaN/±inf value told without one.
NON_FINITE = "non_finite_value"


@dataclass(frozen=True, eq=False)
class Evaluations:
    """Values of one batch and why each evaluation failed.

    Attributes:
        values: ``(n,)`` values — a NumPy array (or anything ``np.asarray`` takes), or for gradient methods
            (``"apgd"``) a torch tensor ``(n,)`` attached by autograd to the input.
        reasons: ``n`` failure codes, ``""`` for a success.

    >>> Evaluations(np.array([3.0, 5000.0]), ("", "no_detection")).reasons
    ('', 'no_detection')
    """

    values: Any
    reasons: tuple[str, ...]

    def __post_init__(self) -> None:
        reasons = tuple(self.reasons) if isinstance(self.reasons, Sequence) else None
        if reasons is None or not all(isinstance(r, str) for r in reasons):
            raise ValueError(f"Evaluations: reasons must be a sequence of strings, got {self.reasons!r}")
        n = int(np.prod(np.shape(self.values))) if not hasattr(self.values, "numel") else int(self.values.numel())
        if len(reasons) != n:
            raise ValueError(f"Evaluations: {len(reasons)} reasons for {n} values")
        object.__setattr__(self, "reasons", reasons)


def split(values: Any) -> tuple[Any, tuple[str, ...] | None]:
    """``(values, reasons)`` of what an objective returned (``reasons`` None for plain values)."""
    if isinstance(values, Evaluations):
        return values.values, values.reasons
    return values, None


def recorded_reasons(values: np.ndarray, reasons: Sequence[str] | None) -> tuple[str, ...]:
    """The reason recorded per point: the given one, else :data:`NON_FINITE` for a NaN/±inf value, else ``""``."""
    given = reasons if reasons is not None else ("",) * len(values)
    finite = np.isfinite(values).tolist()
    return tuple(r or ("" if ok else NON_FINITE) for r, ok in zip(given, finite, strict=True))
