"""The per-image search budget of a campaign block (:class:`Budget`): evaluations, seconds or iterations, early stop
at a breach, and the smaller budgets read off a run's trace. Re-exported by :mod:`vbl_robust.specs.campaign`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Budget:
    """Per-image search budget. At least one of ``max_evals``, ``max_seconds``, ``max_iters`` is set.

    ``stop_at_breach``: stop at the first value above ε_safe (the question "is there a breach?"); off when the
    size of the worst error itself is measured (runtime experiments, convergence).

    ``read_seconds`` / ``read_evals``: smaller budgets *read off* this run's stamped evaluations instead of run
    one by one (for anytime methods, :func:`vbl_robust.search.anytime.at_budget`): the run goes on until ``max_seconds``
    has passed *and* ``max(read_evals)`` evaluations are done, sizing its chunks against each of
    ``read_seconds``; the report shows one result per read budget (:meth:`read_budgets`). Empty for an ordinary
    budget (and then absent from :meth:`to_dict`, so the keys of jobs without them do not change).
    """

    max_evals: int | None = None
    max_seconds: float | None = None
    max_iters: int | None = None
    stop_at_breach: bool = True
    read_seconds: tuple[float, ...] = ()
    read_evals: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if self.max_evals is None and self.max_seconds is None and self.max_iters is None:
            raise ValueError("Budget: give at least one of max_evals, max_seconds, max_iters")
        for name in ("max_evals", "max_iters"):
            v = getattr(self, name)
            if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v < 1):
                raise ValueError(f"Budget: {name} must be an integer >= 1 or None, got {v!r}")
        if self.max_seconds is not None and not (math.isfinite(self.max_seconds) and self.max_seconds > 0):
            raise ValueError(f"Budget: max_seconds must be a finite number > 0 or None, got {self.max_seconds!r}")
        rs = tuple(sorted(float(t) for t in self.read_seconds))
        re_ = tuple(sorted(self.read_evals))
        if rs and (self.max_seconds is None or not all(math.isfinite(t) and 0 < t <= self.max_seconds for t in rs)):
            raise ValueError(f"Budget: read_seconds must lie in (0, max_seconds={self.max_seconds!r}], got {rs!r}")
        if any(not isinstance(n, int) or isinstance(n, bool) or n < 1 for n in re_):
            raise ValueError(f"Budget: read_evals must be integers >= 1, got {re_!r}")
        if re_ and (self.max_seconds is None or (self.max_evals is not None and re_[-1] > self.max_evals)):
            raise ValueError(f"Budget: read_evals {re_!r} need max_seconds and must not exceed max_evals")
        object.__setattr__(self, "read_seconds", rs)
        object.__setattr__(self, "read_evals", re_)

    @property
    def reads(self) -> bool:
        """True when smaller budgets are read off this run."""
        return bool(self.read_seconds or self.read_evals)

    @property
    def min_evals(self) -> int | None:
        """Evaluations the run must reach before its time budget stops it (the largest read evaluation budget)."""
        return max(self.read_evals) if self.read_evals else None

    def read_budgets(self) -> tuple[Budget, ...]:
        """The budgets read off this run: one time budget per ``read_seconds``, one evaluation budget per
        ``read_evals`` (same ``stop_at_breach``)."""
        return (*(Budget(max_seconds=t, stop_at_breach=self.stop_at_breach) for t in self.read_seconds),
                *(Budget(max_evals=n, stop_at_breach=self.stop_at_breach) for n in self.read_evals))

    @property
    def label(self) -> str:
        parts = []
        if self.max_evals is not None:
            parts.append(f"{self.max_evals} evals")
        if self.max_seconds is not None:
            parts.append(f"{self.max_seconds:g} s")
        if self.max_iters is not None:
            parts.append(f"{self.max_iters} iters")
        label = " / ".join(parts)
        if self.read_evals:
            label += f" and ≥ {self.min_evals} evals"
        if self.reads:
            read = [f"{', '.join(f'{t:g}' for t in self.read_seconds)} s"] if self.read_seconds else []
            read += [f"{', '.join(map(str, self.read_evals))} evals"] if self.read_evals else []
            label += f" (read at {'; '.join(read)})"
        return label + ("" if self.stop_at_breach else ", no early stop")

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"max_evals": self.max_evals, "max_seconds": self.max_seconds,
                             "max_iters": self.max_iters, "stop_at_breach": self.stop_at_breach}
        if self.read_seconds:
            d["read_seconds"] = list(self.read_seconds)
        if self.read_evals:
            d["read_evals"] = list(self.read_evals)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Budget:
        return cls(max_evals=d.get("max_evals"), max_seconds=d.get("max_seconds"), max_iters=d.get("max_iters"),
                   stop_at_breach=bool(d.get("stop_at_breach", True)),
                   read_seconds=tuple(d.get("read_seconds", ())), read_evals=tuple(d.get("read_evals", ())))
