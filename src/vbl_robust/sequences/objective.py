"""``SequenceObjective``: the error one θ sustains over an approach sequence, for every search method.

One θ is held over the whole sequence (a steady bank, a lasting contrast change): every frame ``f`` is scored by
its own :class:`~vbl_robust.pipeline.Objective` (perturb → detect → select → PnP → error, failures count
``penalty_m``), and the θ row's value is the error sustained over ``sustain`` consecutive frames
(:func:`.sustain.sustained`). ``objective(theta (n, d))`` returns
:class:`~vbl_robust.search.Evaluations`; :meth:`SequenceObjective.torch` the differentiable twin (APGD), built
from each frame's :meth:`Objective.torch`.

Failure reason of a θ row: ``""`` unless every frame of the window that sets the value failed; then the
failure code of the window's first frame (the value is then the penalty).

Frame batching
    With a detector that reads pixels (``uses_pixels``) and frames of one size and camera, the views of all
    frames for a θ batch go through the detector together: rows (frame, θ) are cut into chunks of ``batch_size``
    that may span frames, each chunk one ``detect`` (or ``detect_top``) call on a context whose view sampler
    stacks the frames' samplers; the detections are then handed to each frame's ``Objective``, which selects,
    solves PnP and scores as usual. The detector must not read ``context.sample`` or move points on such a
    context (the oracle does: it is always called per frame, as is any detector with ``uses_pixels = False``).
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
from vbl_robust.perturb import PERTURBATIONS
from vbl_robust.pipeline import EvalRecord, Objective
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

    def __len__(self) -> int:
        return int(self.value.shape[0])

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


class _FrameReplay:
    """A frame's detector: hands out the detections computed for the whole batch, else calls the detector."""

    def __init__(self, detector) -> None:
        self.detector = detector
        self.input_size = getattr(detector, "input_size", None)
        self.uses_pixels = getattr(detector, "uses_pixels", True)
        self.differentiable = getattr(detector, "differentiable", False)
        self.clear()

    def __repr__(self) -> str:
        return repr(self.detector)

    def clear(self) -> None:
        self.dets: list | None = None
        self.top: tuple[torch.Tensor, torch.Tensor] | None = None
        self.pos = 0

    def _take(self, n: int, total: int) -> slice:
        if self.pos + n > total:
            raise RuntimeError(f"SequenceObjective: frame asked for {self.pos + n} detections, {total} were computed")
        s = slice(self.pos, self.pos + n)
        self.pos += n
        return s

    def detect(self, context):
        if self.dets is None:
            return self.detector.detect(context)
        return self.dets[self._take(len(context), len(self.dets))]

    def detect_top(self, context):
        if self.top is None:
            return self.detector.detect_top(context)
        conf, kp = self.top
        s = self._take(len(context), int(conf.shape[0]))
        return conf[s], kp[s]


class SequenceObjective:
    """``S_k(θ)`` of one approach sequence: ``objective(theta (n, d)) -> Evaluations`` (metres).

    Args:
        sequence: an :class:`~vbl_robust.data.ApproachSequence` (or a list of samples in flight order).
        detector, box, pnp, conf_threshold, penalty_m, batch_size, resolution, pnp_grad: as for
            :class:`~vbl_robust.pipeline.Objective` (one per frame); ``batch_size`` also bounds the rows of one
            frame-batched detector call.
        sustain: ``k``, frames the error must hold (1 = the worst frame).
        batch_frames: True: batch the frames through the detector when it reads pixels and the frames share a
            size and camera (module docstring); False: call it per frame.

    >>> import vbl_robust as vr                                                          # doctest: +SKIP
    >>> seq = vr.scenes.generate_sequences(1, 20, 10.0, seed=0)[0]                       # doctest: +SKIP
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
        self._replays = [_FrameReplay(detector) for _ in sequence.samples] if batch_frames else []
        self.frames = [
            Objective(s, self._replays[f] if self._replays else detector, box, pnp, conf_threshold=conf_threshold,
                      penalty_m=penalty_m, batch_size=batch_size, resolution=resolution, pnp_grad=pnp_grad)
            for f, s in enumerate(sequence.samples)
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
    def batched(self) -> bool:
        """Whether the frames go through the detector together (decided on first use: it loads the pixels)."""
        if self._batchable is None:
            ok = bool(self._replays) and getattr(self.detector, "uses_pixels", True)
            live = [o for o in self.frames if not o.image_error] if ok else []
            if ok and live:
                first = live[0]
                ok = all(o.scale == first.scale and (o.sample.width, o.sample.height) == (first.sample.width,
                         first.sample.height) and np.array_equal(o.sample.K, first.sample.K) for o in live)
            self._batchable = bool(ok and len(live) > 1)
        return self._batchable

    # -- entry points ------------------------------------------------------------------------------------------
    def __call__(self, theta) -> Evaluations:
        """``theta (n, d)`` real units → :class:`Evaluations` (``S_k`` in metres, failure reasons)."""
        rec = self.evaluate(theta)
        return Evaluations(rec.value, rec.reason)

    def evaluate(self, theta) -> SequenceRecord:
        """Like ``__call__`` with the per-frame errors, reasons and records."""
        t = self.frames[0].perturbation.check_theta(np.asarray(theta, dtype=np.float64))
        recs = self._per_frame(t, lambda obj: obj.evaluate(t))
        loss = np.stack([r.loss for r in recs])
        reasons = [r.reason for r in recs]
        value, start = sustained(loss, self.sustain) if t.shape[0] else (np.zeros(0), np.zeros(0, dtype=int))
        seq = self.sequence
        return SequenceRecord(str(seq.id), self.names, self.sustain, t, loss, tuple(reasons), value, start,
                              _row_reasons(reasons, start, self.sustain), tuple(recs), seq.distances_m,
                              np.asarray(seq.times, dtype=np.float64))

    def torch(self, theta) -> Evaluations:
        """``theta (n, d)`` tensor → :class:`Evaluations` whose values are a ``(n,)`` float64 tensor differentiable
        w.r.t. θ (the per-frame :meth:`Objective.torch` through min over windows and max over windows)."""
        t = theta if isinstance(theta, torch.Tensor) else torch.as_tensor(np.asarray(theta, dtype=np.float64))
        outs = self._per_frame(t, lambda obj: obj.torch(t, reasons=True))
        loss = torch.stack([o[0] for o in outs])
        reasons = [tuple(o[1]) for o in outs]
        value = sustained_torch(loss, self.sustain)
        _, start = sustained(loss.detach().cpu().numpy(), self.sustain)
        return Evaluations(value, _row_reasons(reasons, start, self.sustain))

    # -- one loop over the frames --------------------------------------------------------------------------------
    def _per_frame(self, t, run):
        n = int(t.shape[0])
        self.nfev += n
        try:
            if n and self.batched:
                self._prefetch(t)
            return [run(obj) for obj in self.frames]
        finally:
            for r in self._replays:
                r.clear()

    def _prefetch(self, t) -> None:
        """Detect every (frame, θ row) in chunks spanning frames; hand each frame its detections."""
        grad = isinstance(t, torch.Tensor)
        n = int(t.shape[0])
        live = [f for f, o in enumerate(self.frames) if not o.image_error]
        dets: dict[int, list] = {f: [] for f in live}
        tops: dict[int, list] = {f: [] for f in live}
        total = len(live) * n
        for a in range(0, total, self.batch_size):
            b = min(a + self.batch_size, total)
            pieces = []
            for p in range(a // n, (b - 1) // n + 1):
                i0, i1 = max(a - p * n, 0), min(b - p * n, n)
                pieces.append((live[p], i1 - i0, self.frames[live[p]].context(t[i0:i1])))
            ctx = pieces[0][2] if len(pieces) == 1 else dataclasses.replace(
                pieces[0][2], sampler=_StackedViews([c.sampler for _, _, c in pieces]))
            if grad:
                conf, kp = self.detector.detect_top(ctx)
                for (f, _, _), c, k in zip(pieces, conf.split([m for _, m, _ in pieces]),
                                           kp.split([m for _, m, _ in pieces]), strict=True):
                    tops[f].append((c, k))
            else:
                with torch.no_grad():
                    out = list(self.detector.detect(ctx))
                if len(out) != b - a:
                    raise ValueError(f"SequenceObjective: detector {self.detector!r} returned {len(out)} results for "
                                     f"{b - a} images")
                pos = 0
                for f, m, _ in pieces:
                    dets[f].extend(out[pos:pos + m])
                    pos += m
        for f in live:
            if grad:
                self._replays[f].top = (torch.cat([c for c, _ in tops[f]]), torch.cat([k for _, k in tops[f]]))
            else:
                self._replays[f].dets = dets[f]
