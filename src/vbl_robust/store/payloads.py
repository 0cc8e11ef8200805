"""What a job row's payload holds (``JobRow.payload``, stored as JSON), one class per kind, each the one place its
keys are named: the worker writes it (``to_json``) and every reader reads it back (``of``: None for a row without
one). ``JobRow.payload`` keeps the JSON as stored — a class never rewrites a stored payload (a merge copies it as it
is and its digest covers its bytes) — so ``of(row)`` reads; it does not replace. Older rows may lack a key written
later: it reads as None.

- :class:`WorstPayload` — a main image search's worst point (:class:`WorstPoint`) and its image unperturbed
  (:class:`Nominal`); payload ``{"worst", "nominal"}``;
- :class:`SequencePayload` — a sequence search's frames (:class:`SequenceFrames`) and the breach facts of its worst
  θ and of the unperturbed θ (:class:`SequenceFacts`); payload ``{"sequence"}``;
- :class:`RiskPayload` — a failure-probability estimate (its strata: :class:`RiskStratum`); payload ``{"risk"}``.

Imports nothing of the package: the module that writes payloads (``campaigns.work``) and those that read them
(``analysis``, ``report``) import this one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol


class _HasPayload(Protocol):
    payload: Mapping[str, Any] | None


def _pairs(v: Sequence[Sequence[float]] | None) -> tuple[tuple[float, ...], ...] | None:
    return None if v is None else tuple(tuple(c) for c in v)


def _lists(v: Sequence[Sequence[float]] | None) -> list[list[float]] | None:
    return None if v is None else [list(c) for c in v]


@dataclass(frozen=True)
class WorstPoint:
    """The pipeline at a search's worst point (payload ``worst``; one more evaluation there).

    Attributes:
        conf: the selected candidate's confidence (None: not finite).
        error_m: the position error, metres (None: not finite).
        position: the estimated camera position ``(x, y, z)``, metres, runway frame.
        corner_sigma_px: a detector that says how sure it is: each corner's σ ``(σu, σv)``, the sample's pixels
            (4 × 2; None for other detectors); ``position_sigma_m``: that σ propagated to the position, metres.
    """

    conf: float | None = None
    error_m: float | None = None
    position: tuple[float | None, ...] | None = None
    corner_sigma_px: tuple[tuple[float | None, ...], ...] | None = None
    position_sigma_m: float | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"conf": self.conf, "error_m": self.error_m,
                               "position": None if self.position is None else list(self.position)}
        if self.corner_sigma_px is not None:
            out["corner_sigma_px"] = _lists(self.corner_sigma_px)
            out["position_sigma_m"] = self.position_sigma_m
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WorstPoint:
        pos = d.get("position")
        return cls(d.get("conf"), d.get("error_m"), None if pos is None else tuple(pos),
                   _pairs(d.get("corner_sigma_px")), d.get("position_sigma_m"))


@dataclass(frozen=True)
class Nominal:
    """The image unperturbed (payload ``nominal``; one evaluation at the identity θ: roll 0, contrast 1, …).

    Attributes:
        error_m: L(0), metres (the objective: the failure penalty where it failed; None: not finite).
        reason: the failure reason (``""``: a pose).
        conf: the selected candidate's confidence (None: not finite).
        corners: the predicted corners, the sample's pixels, TR TL BL BR (None: none).
    """

    error_m: float | None = None
    reason: str | None = None
    conf: float | None = None
    corners: tuple[tuple[float, ...], ...] | None = None

    def to_json(self) -> dict[str, Any]:
        return {"error_m": self.error_m, "reason": self.reason, "conf": self.conf, "corners": _lists(self.corners)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Nominal:
        return cls(d.get("error_m"), d.get("reason"), d.get("conf"), _pairs(d.get("corners")))


@dataclass(frozen=True)
class WorstPayload:
    """A main image search's payload: its worst point and its image unperturbed (None in rows stored before it
    was recorded)."""

    worst: WorstPoint
    nominal: Nominal | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"worst": self.worst.to_json()}
        if self.nominal is not None:
            out["nominal"] = self.nominal.to_json()
        return out

    @classmethod
    def of(cls, row: _HasPayload) -> WorstPayload | None:
        p = row.payload
        if not p or not (p.get("worst") or p.get("nominal")):
            return None
        return cls(WorstPoint.from_json(p.get("worst") or {}),
                   Nominal.from_json(p["nominal"]) if p.get("nominal") else None)


@dataclass(frozen=True)
class SequenceFrames:
    """The frames of an approach sequence (payload ``sequence.frames``): each frame's image id, index in its
    approach, time (s, None: not finite) and distance from the runway threshold (m)."""

    image: tuple[str, ...]
    frame_index: tuple[int, ...]
    time_s: tuple[float | None, ...]
    distance_m: tuple[float, ...]

    def to_json(self) -> dict[str, Any]:
        return {f.name: list(getattr(self, f.name)) for f in dataclasses.fields(self)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SequenceFrames:
        return cls(*(tuple(d.get(f.name) or ()) for f in dataclasses.fields(cls)))


#: The breach facts of one θ over a sequence, in their stored order after θ
#: (:func:`vbl_robust.sequences.sustain.breach_summary`, then the reason and the failed frames).
_FACTS = ("sustained_m", "window_start", "breached_frames", "longest_run_frames", "longest_run_start",
          "longest_run_s", "breach_start_frame", "breach_start_m", "first_breach_m", "reason", "failed_frames")


@dataclass(frozen=True)
class SequenceFacts:
    """What one θ does over a sequence (payload ``sequence.worst`` / ``sequence.nominal``): the sequence, ``sustain``
    k and its frame count, θ by name, the breach facts (:func:`~vbl_robust.sequences.sustain.breach_summary`: the
    error sustained over k frames, the breached frames, the longest breached run, where a lasting breach starts),
    the reason of the sustained window and the failed frames, and each frame's error (m, None: not finite) and
    failure reason."""

    sequence_id: str
    sustain: int
    frames: int
    theta: Mapping[str, float] = field(default_factory=dict)
    sustained_m: float | None = None
    window_start: int | None = None
    breached_frames: int | None = None
    longest_run_frames: int | None = None
    longest_run_start: int | None = None
    longest_run_s: float | None = None
    breach_start_frame: int | None = None
    breach_start_m: float | None = None
    first_breach_m: float | None = None
    reason: str | None = None
    failed_frames: int | None = None
    errors_m: tuple[float | None, ...] = ()
    reasons: tuple[str, ...] = ()

    @classmethod
    def of_summary(cls, summary: Mapping[str, Any], errors_m: Sequence[float | None],
                   reasons: Sequence[str]) -> SequenceFacts:
        """From a :meth:`~vbl_robust.sequences.objective.SequenceRecord.summary` (θ: its keys that name no fact)."""
        head = ("sequence_id", "sustain", "frames")
        theta = {k: v for k, v in summary.items() if k not in (*head, *_FACTS, "errors_m", "reasons")}
        return cls(*(summary[k] for k in head), theta, *(summary.get(k) for k in _FACTS), tuple(errors_m),
                   tuple(reasons))

    def to_json(self) -> dict[str, Any]:
        return {"sequence_id": self.sequence_id, "sustain": self.sustain, "frames": self.frames, **self.theta,
                **{k: getattr(self, k) for k in _FACTS}, "errors_m": list(self.errors_m), "reasons": list(self.reasons)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SequenceFacts:
        return cls.of_summary(d, d.get("errors_m") or (), d.get("reasons") or ())


@dataclass(frozen=True)
class SequencePayload:
    """A sequence search's payload: the frames, and the facts of its worst θ and of the unperturbed θ."""

    frames: SequenceFrames
    worst: SequenceFacts
    nominal: SequenceFacts

    def to_json(self) -> dict[str, Any]:
        return {"sequence": {"frames": self.frames.to_json(), "worst": self.worst.to_json(),
                             "nominal": self.nominal.to_json()}}

    @classmethod
    def of(cls, row: _HasPayload) -> SequencePayload | None:
        seq = (row.payload or {}).get("sequence")
        if not seq:
            return None
        return cls(SequenceFrames.from_json(seq["frames"]), SequenceFacts.from_json(seq["worst"]),
                   SequenceFacts.from_json(seq["nominal"]))


@dataclass(frozen=True)
class RiskStratum:
    """A stratum of a guided estimate: its probability ``mass``, ``k`` failures of ``n`` draws, and its shares of δ
    for the lower and upper bound (None in rows written with the even split)."""

    mass: float
    k: int
    n: int
    share_low: float | None = None
    share_high: float | None = None

    def to_json(self) -> dict[str, Any]:
        out = {"mass": self.mass, "k": self.k, "n": self.n}
        if self.share_low is not None or self.share_high is not None:
            out.update(share_low=self.share_low, share_high=self.share_high)
        return out


@dataclass(frozen=True)
class RiskPayload:
    """A failure-probability job's payload (:mod:`vbl_robust.risk`): the estimator, ``p_fail`` and its
    interval (``ci_low``, ``ci_high`` at ``ci_level``, by ``ci_method``), the ε_safe it counts failures above, the
    verdict on p_fail ≤ ``tau`` at confidence 1 − ``delta``, the evaluations, the θ distribution (``{name: {"kind",
    "mu", "sigma"}}``) and the strata of a guided estimate (empty for mc)."""

    method: str
    p_fail: float
    eps_safe_m: float
    ci_low: float
    ci_high: float
    ci_level: float
    ci_method: str
    verdict: str
    tau: float
    delta: float
    evaluations: int
    distribution: Mapping[str, Any] = field(default_factory=dict)
    strata: tuple[RiskStratum, ...] = ()

    def to_json(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["strata"] = [s.to_json() for s in self.strata]
        return {"risk": d}

    @classmethod
    def of(cls, row: _HasPayload) -> RiskPayload | None:
        d = (row.payload or {}).get("risk")
        if not d:
            return None
        strata = tuple(RiskStratum(s["mass"], s["k"], s["n"], s.get("share_low"), s.get("share_high"))
                       for s in d.get("strata") or ())
        return cls(**{f.name: d.get(f.name) for f in dataclasses.fields(cls) if f.name != "strata"}, strata=strata)
