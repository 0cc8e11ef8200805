"""``SequenceObjective``: the error one θ sustains over an approach sequence, for every search method.

One θ is held over the whole sequence (a steady bank, a lasting contrast change): every frame ``f`` is scored by
its own :class:`~vbl_robust.pipeline.Objective` (perturb → detect → select → PnP → error, failures count
``penalty_m``), and the θ row's value is the error sustained over ``sustain`` consecutive frames
(:func:`.sustain.sustained`). The contract is the frame objective's (:mod:`vbl_robust.pipeline`):
``objective(theta (n, d))`` returns :class:`~vbl_robust.search.evaluations.Evaluations` and :meth:`SequenceObjective.evaluate`
the full :class:`SequenceRecord`; a torch θ gives values differentiable w.r.t. it (APGD), through each frame's
differentiable path.

Failure reason of a θ row: ``""`` unless every frame of the window that sets the value failed; then the
failure code of the window's first frame (the value is then the penalty).

Frame batching
    With a detector that reads pixels (``uses_pixels``) and frames of one size and camera, the views of all
    frames for a θ batch go through the detector together: rows (frame, θ) are cut into chunks of ``batch_size``
    that may span frames, each chunk one ``detect`` (or ``detect_top``) call on a context whose view sampler
    stacks the frames' samplers; each frame's ``Objective`` then turns its rows into a selection
    (:meth:`~vbl_robust.pipeline.Objective.selection`) and scores them (:meth:`~vbl_robust.pipeline.Objective.locate`:
    PnP and the error). The detector must not read ``context.sample`` or move points on such a context (the
    oracle does: it is always called per frame, as is any detector with ``uses_pixels = False``).
    ``batch_frames=False`` calls the detector per frame; both give the same detections up to the float rounding
    that the composition of a network batch changes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from vbl_robust.constants import CONF_THRESHOLD, EPS_SAFE_M, PENALTY_M
from vbl_robust.data.sample import Sample
from vbl_robust.data.sequence import ApproachSequence
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.pipeline import EvalRecord, Objective, detector_name
from vbl_robust.search.evaluations import Evaluations
from vbl_robust.space import ParameterBox

from .sustain import breach_summary, check_sustain, sustained, sustained_torch

__all__ = ["SequenceObjective", "SequenceRecord", "nominal_theta"]


def nominal_theta(box: ParameterBox) -> np.ndarray:
    """``(1, d)`` the unperturbed θ (every parameter at its identity value: roll 0°, contrast 1)."""
    return np.array([[PERTURBATIONS[n].identity for n in box.names]], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class SequenceRecord:
    """Every detail of a batch of θ rows over one sequence.

    Attributes:
        sequence_id: the sequence's id; names: parameter names; sustain: ``k``.
        theta: ``(n, d)`` real units.
        loss: ``(F, n)`` per-frame ``L`` (metres, ``penalty_m`` where the frame failed).
        reasons: ``F`` tuples of ``n`` per-frame failure codes (``""`` = success).
        value: ``(n,)`` sustained error ``S_k``; window_start: ``(n,)`` first frame of its window.
        reason: ``n`` row failure codes (module docstring).
        frames: the ``F`` per-frame :class:`~vbl_robust.pipeline.EvalRecord` (positions, confidences, keypoints).
        distances_m, times_s: ``(F,)`` of the sequence (horizontal distance from the LTP; seconds).
        value_t: the differentiable path only: ``value`` as a ``(n,)`` float64 tensor attached to θ (else None).
    """

    sequence_id: str
    names: tuple[str, ...]
    sustain: int
    theta: np.ndarray
    loss: np.ndarray
    reasons: tuple[tuple[str, ...], ...]
    value: np.ndarray
    window_start: np.ndarray
    reason: tuple[str, ...]
    frames: tuple[EvalRecord, ...]
    distances_m: np.ndarray
    times_s: np.ndarray
    value_t: torch.Tensor | None = None

    def __len__(self) -> int:
        return int(self.value.shape[0])

    def evaluations(self) -> Evaluations:
        """What a search receives: the sustained errors (the tensor on the differentiable path) and the reasons."""
        return Evaluations(self.value if self.value_t is None else self.value_t, self.reason)

    def summary(self, i: int = 0, eps_m: float = EPS_SAFE_M) -> dict:
        """Breach facts of row ``i`` (:func:`.sustain.breach_summary`) with θ by name and the row's reason."""
        out = {"sequence_id": self.sequence_id, "sustain": self.sustain, "frames": int(self.loss.shape[0])}
        out.update({n: float(v) for n, v in zip(self.names, self.theta[i], strict=True)})
        out.update(breach_summary(self.loss[:, i], self.distances_m, self.times_s, self.sustain, eps_m))
        out["reason"] = self.reason[i]
        out["failed_frames"] = sum(1 for r in self.reasons if r[i])
        return out


def _row_reasons(reasons: list[tuple[str, ...]], start: np.ndarray, k: int) -> tuple[str, ...]:
    out = []
    for i, j in enumerate(start.tolist()):
        window = [reasons[f][i] for f in range(j, j + k)]
        out.append(window[0] if all(window) else "")
    return tuple(out)


class _StackedViews:
    """The view-sampler interface over the samplers of several frames (rows of one after the other's)."""

    def __init__(self, samplers: Sequence) -> None:
        self.samplers = list(samplers)
        self.lengths = [len(s) for s in self.samplers]
        self.perturbation = self.samplers[0].perturbation
        thetas = [s.theta for s in self.samplers]
        self.theta = torch.cat(thetas) if isinstance(thetas[0], torch.Tensor) else np.concatenate(thetas)

    def __len__(self) -> int:
        return sum(self.lengths)

    @property
    def differentiable(self) -> bool:
        return isinstance(self.theta, torch.Tensor)

    @property
    def height(self) -> int:
        return self.samplers[0].height

    @property
    def width(self) -> int:
        return self.samplers[0].width

    @property
    def device(self) -> torch.device:
        return self.samplers[0].device

    def frames(self) -> torch.Tensor:
        return torch.cat([s.frames() for s in self.samplers])

    def views(self, windows, size: int, **options) -> torch.Tensor:
        w = torch.as_tensor(windows)
        parts = [w] * len(self.samplers) if w.ndim == 1 else list(w.split(self.lengths))
        return torch.cat([s.views(p, size, **options) for s, p in zip(self.samplers, parts, strict=True)])

    def points(self, points):
        raise ValueError("a frame-batched context holds several frames: a detector that moves points needs "
                         "SequenceObjective(batch_frames=False)")


class SequenceObjective:
    """``S_k(θ)`` of one approach sequence: ``objective(theta (n, d)) -> Evaluations`` (metres).

    Args:
        sequence: an :class:`~vbl_robust.data.sequence.ApproachSequence` (or a list of samples in flight order).
        detector, box, pnp, conf_threshold, penalty_m, batch_size, resolution, pnp_grad: as for
            :class:`~vbl_robust.pipeline.Objective` (one per frame); ``batch_size`` also bounds the rows of one
            frame-batched detector call.
        sustain: ``k``, frames the error must hold (1 = the worst frame).
        batch_frames: True: batch the frames through the detector when it reads pixels and the frames share a
            size and camera (module docstring); False: call it per frame.

    >>> import vbl_robust as vr                                                          # doctest: +SKIP
    >>> from vbl_robust.scenes.sequences import generate_sequences                       # doctest: +SKIP
    >>> seq = generate_sequences(1, 20, 10.0, seed=0)[0]                                 # doctest: +SKIP
    >>> f = SequenceObjective(seq, vr.OracleDetector(), box, sustain=5)                  # doctest: +SKIP
    >>> vr.search.maximize(f, box, "georobust", max_evals=100).fun                       # doctest: +SKIP
    """

    def __init__(
        self,
        sequence: ApproachSequence | Sequence[Sample],
        detector,
        box: ParameterBox,
        pnp: str = "ippe_lm",
        *,
        sustain: int = 1,
        conf_threshold: float = CONF_THRESHOLD,
        penalty_m: float = PENALTY_M,
        batch_size: int = 32,
        resolution: str | int = "auto",
        pnp_grad: str = "exact",
        batch_frames: bool = True,
    ):
        if not isinstance(sequence, ApproachSequence):
            samples = list(sequence)
            sequence = ApproachSequence("sequence", samples, np.full(len(samples), np.nan), np.arange(len(samples)))
        if not isinstance(batch_frames, bool):
            raise ValueError(f"SequenceObjective: batch_frames must be True or False, got {batch_frames!r}")
        self.sequence = sequence
        self.sustain = check_sustain(sustain, len(sequence))
        self.detector = detector
        self.box = box
        self.batch_frames = batch_frames
        self.batch_size = batch_size
        self.frames = [
            Objective(s, detector, box, pnp, conf_threshold=conf_threshold, penalty_m=penalty_m,
                      batch_size=batch_size, resolution=resolution, pnp_grad=pnp_grad)
            for s in sequence.samples
        ]
        self.penalty_m = float(penalty_m)
        self.nfev = 0
        self._batchable: bool | None = None

    def __repr__(self) -> str:
        return (f"SequenceObjective(sequence={self.sequence.id!r}, frames={len(self.sequence)}, "
                f"sustain={self.sustain}, detector={self.detector!r}, box={self.box!r})")

    @property
    def names(self) -> tuple[str, ...]:
        return self.box.names

    @property
    def dim(self) -> int:
        return self.box.dim

    @property
    def device(self) -> torch.device:
        """Where the frames are evaluated (every frame's objective runs on the same device)."""
        return self.frames[0].device

    @property
    def image_error(self) -> str:
        """Why a frame's pixels could not be loaded (``""`` when every frame's could): a sequence with a missing
        frame is a failed sample of a campaign, not a breach (its frame would count the penalty)."""
        for s, o in zip(self.sequence.samples, self.frames, strict=True):
            if o.image_error:
                return f"frame {s.id}: {o.image_error}"
        return ""

    @property
    def batched(self) -> bool:
        """Whether the frames go through the detector together (decided on first use: it loads the pixels)."""
        if self._batchable is None:
            ok = self.batch_frames and getattr(self.detector, "uses_pixels", True)
            live = [o for o in self.frames if not o.image_error] if ok else []
            if ok and live:
                first = live[0]
                ok = all(o.scale == first.scale and (o.sample.width, o.sample.height) == (first.sample.width,
                         first.sample.height) and np.array_equal(o.sample.K, first.sample.K) for o in live)
            self._batchable = bool(ok and len(live) > 1)
        return self._batchable

    # -- the contract (module docstring) ---------------------------------------------------------------------
    def __call__(self, theta) -> Evaluations:
        """``theta (n, d)`` real units → :class:`Evaluations` (``S_k`` in metres, failure reasons; a tensor
        differentiable w.r.t. a torch θ)."""
        return self.evaluate(theta).evaluations()

    def evaluate(self, theta) -> SequenceRecord:
        """Like ``__call__`` with the per-frame errors, reasons and records."""
        grad = isinstance(theta, torch.Tensor)
        if grad:
            self.frames[0].check_differentiable()
        check = self.frames[0].perturbation.check_theta
        t = check(theta) if grad else check(np.asarray(theta, dtype=np.float64))
        n = int(t.shape[0])
        self.nfev += n
        recs = self._per_frame(t)
        loss = np.stack([r.loss for r in recs]) if recs else np.zeros((0, n))
        reasons = [r.reason for r in recs]
        value, start = sustained(loss, self.sustain) if n else (np.zeros(0), np.zeros(0, dtype=int))
        value_t = None
        if grad:  # attached to θ even where every frame failed (a constant penalty)
            value_t = sustained_torch(torch.stack([r.loss_t for r in recs]), self.sustain) + 0.0 * t.sum(dim=1).to(torch.float64)
        seq = self.sequence
        return SequenceRecord(str(seq.id), self.names, self.sustain,
                              t.detach().cpu().numpy().astype(np.float64) if grad else t, loss, tuple(reasons), value,
                              start, _row_reasons(reasons, start, self.sustain), tuple(recs), seq.distances_m,
                              np.asarray(seq.times, dtype=np.float64), value_t)

    # -- the frames ------------------------------------------------------------------------------------------------
    def _per_frame(self, t) -> list[EvalRecord]:
        """Every frame's :class:`EvalRecord` for θ rows ``t``: detected together when the frames batch."""
        if not (int(t.shape[0]) and self.batched):
            return [obj.evaluate(t) for obj in self.frames]
        raw = self._detect_all(t)
        return [obj.evaluate(t) if f not in raw else obj.locate(t, obj.selection(raw[f], int(t.shape[0])))
                for f, obj in enumerate(self.frames)]

    def _detect_all(self, t) -> dict[int, object]:
        """Detect every (frame, θ row) in chunks spanning frames: per frame with pixels, the detector's raw output
        for its rows (a list of detections, or ``detect_top``'s ``(conf, keypoints)``)."""
        grad = isinstance(t, torch.Tensor)
        n = int(t.shape[0])
        live = [f for f, o in enumerate(self.frames) if not o.image_error]
        parts: dict[int, list] = {f: [] for f in live}
        total = len(live) * n
        for a in range(0, total, self.batch_size):
            b = min(a + self.batch_size, total)
            pieces = []
            for p in range(a // n, (b - 1) // n + 1):
                i0, i1 = max(a - p * n, 0), min(b - p * n, n)
                pieces.append((live[p], i1 - i0, self.frames[live[p]].context(t[i0:i1])))
            ctx = pieces[0][2] if len(pieces) == 1 else dataclasses.replace(
                pieces[0][2], sampler=_StackedViews([c.sampler for _, _, c in pieces]))
            sizes = [m for _, m, _ in pieces]
            if grad:
                conf, kp = self.detector.detect_top(ctx)
                for (f, _, _), c, k in zip(pieces, conf.split(sizes), kp.split(sizes), strict=True):
                    parts[f].append((c, k))
            else:
                with torch.no_grad():
                    out = list(self.detector.detect(ctx))
                if len(out) != b - a:
                    raise ValueError(f"SequenceObjective: detector {detector_name(self.detector)} returned "
                                     f"{len(out)} results for {b - a} images")
                pos = 0
                for f, m in zip((f for f, _, _ in pieces), sizes, strict=True):
                    parts[f].extend(out[pos:pos + m])
                    pos += m
        if grad:
            return {f: (torch.cat([c for c, _ in ps]), torch.cat([k for _, k in ps])) for f, ps in parts.items()}
        return parts
