"""The end-to-end error ``L(θ)`` of one sample: perturb → detect → select → PnP → position error.

For a sample (image ``x``, intrinsics ``K``, runway corners, true camera position ``y``) and a batch of
parameter vectors θ ``(N, d)`` in real units (columns named by the box)::

    views = ViewSampler(x, θ)         the perturbed images T(x; θ), as the views a detector asks for (perturb/)
    k     = σ_select(detector(views))  max-confidence candidate if conf ≥ τ_conf (detect/)
    ŷ     = PnP(k, corners_3d, K)      camera position in the runway frame (pnp/)
    L     = ‖ŷ − y‖₂  (metres), or PENALTY_M (5000 m) on ANY failure

One contract for every objective (this one and :class:`~vbl_robust.sequences.objective.SequenceObjective`):
``objective(theta)`` returns :class:`~vbl_robust.search.evaluations.Evaluations` (values in metres and a failure reason per
row) and :meth:`Objective.evaluate` the full :class:`EvalRecord`; the type of θ picks the mode. A NumPy θ is the
black box (no gradient, OpenCV PnP); a torch θ the differentiable path (the detector's ``detect_top`` and the
implicit PnP gradient; the values are a float64 tensor attached to θ; penalised rows are constant with zero
gradient, never NaN). Each chunk of θ is two steps: :meth:`Objective.select_at` (one detector call and σ_select →
a :class:`~vbl_robust.detect.base.Selection`) and :meth:`Objective.locate` (PnP and the error → an
:class:`EvalRecord`); an objective over several frames batches the first step across frames and scores each
frame with the second. Both modes record per row why an evaluation failed
(:data:`vbl_robust.constants.FAILURE_REASONS`): ``no_detection``, ``low_confidence``, ``non_finite_keypoints``, ``pnp_failed``,
``non_finite_position``. A successful row is never capped: a wild but "successful" PnP can exceed the penalty.
What the tool cannot do is no failure of the pipeline and is never scored: pixels that cannot be loaded, or a torch
θ on a detector without gradients, raise :class:`~vbl_robust.constants.NotMeasuredError` (a campaign records the
job as not measured).

Resolution: the image is resized once to the detector's ``input_size`` (long side) when that is smaller —
rotation about the principal point commutes with isotropic scaling, so this is the same perturbation on fewer
pixels; keypoints are mapped back to the sample's pixels before PnP (``resolution="full"`` disables it).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch

from vbl_robust.constants import CONF_THRESHOLD, PENALTY_M, FailureReason, NotMeasured, NotMeasuredError
from vbl_robust.data.sample import Sample
from vbl_robust.detect.base import DetectContext, Detector, Selection, select
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.resample import PixelScale, resize_image
from vbl_robust.perturb.views import ViewSampler
from vbl_robust.pnp.differentiable import pnp_position_torch, position_sigma
from vbl_robust.pnp.solvers import SOLVERS, solve
from vbl_robust.search.evaluations import Evaluations
from vbl_robust.space import ParameterBox

logger = logging.getLogger(__name__)

__all__ = ["FAILURE_REASONS", "EvalRecord", "Objective", "SearchObjective"]

#: The failure codes of :attr:`EvalRecord.reason` (see :data:`vbl_robust.constants.FAILURE_REASONS`).
FAILURE_REASONS = tuple(r.value for r in FailureReason)


@dataclass(frozen=True, eq=False)
class EvalRecord:
    """Everything about one batch of evaluations of one sample, row ``i`` for ``theta[i]``.

    Attributes:
        sample_id: the sample's id.
        names: parameter names (columns of ``theta``).
        theta: ``(N, d)`` parameters, real units.
        loss: ``(N,)`` ``L(θ)`` in metres (``penalty_m`` where failed).
        error_m: ``(N,)`` position error ‖ŷ − y‖ in metres, NaN where failed.
        position: ``(N, 3)`` estimated camera position in the runway frame, NaN where not estimated.
        conf: ``(N,)`` confidence of the top candidate (NaN when there was none).
        keypoints: ``(N, 4, 2)`` selected keypoints in the sample's pixels (NaN when none was selected).
        reproj_error_px: ``(N,)`` RMS reprojection error of the PnP solution, pixels (NaN where failed).
        reason: ``N`` failure codes from :data:`FAILURE_REASONS`, ``""`` for a success.
        detail: ``N`` free-text details (PnP's reason, the image error), ``""`` when none.
        penalty_m: the penalty used.
        loss_t: the differentiable path only: ``loss`` as a ``(N,)`` float64 tensor attached to θ (else None).
        keypoint_sigma: ``(N, 4, 2)`` the selected corners' σ in the sample's pixels, from a detector with an
            uncertainty head (NaN elsewhere); None when the detector gives none.
        position_sigma_m: ``(N,)`` those σ propagated through PnP to the position, metres
            (:func:`~vbl_robust.pnp.differentiable.position_sigma`; NaN where no pose); None when the detector gives no σ.
    """

    sample_id: str
    names: tuple[str, ...]
    theta: np.ndarray
    loss: np.ndarray
    error_m: np.ndarray
    position: np.ndarray
    conf: np.ndarray
    keypoints: np.ndarray
    reproj_error_px: np.ndarray
    reason: tuple[str, ...]
    detail: tuple[str, ...]
    penalty_m: float = PENALTY_M
    loss_t: torch.Tensor | None = None
    keypoint_sigma: np.ndarray | None = None
    position_sigma_m: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.loss.shape[0])

    def evaluations(self) -> Evaluations:
        """What a search receives: the losses (the tensor on the differentiable path) and the failure reasons."""
        return Evaluations(self.loss if self.loss_t is None else self.loss_t, self.reason)

    @property
    def failed(self) -> np.ndarray:
        """``(N,)`` True where the row was penalised."""
        return np.array([r != "" for r in self.reason], dtype=bool)

    def to_rows(self) -> list[dict]:
        """One flat JSON-friendly dict per row (for reports and result stores)."""
        rows = []
        for i in range(len(self)):
            row = {"sample_id": self.sample_id}
            row.update({n: float(v) for n, v in zip(self.names, self.theta[i], strict=True)})
            row.update(loss_m=float(self.loss[i]), error_m=float(self.error_m[i]), conf=float(self.conf[i]),
                       reproj_error_px=float(self.reproj_error_px[i]), reason=self.reason[i],
                       detail=self.detail[i])
            row.update({f"position_{a}": float(v) for a, v in zip("xyz", self.position[i], strict=True)})
            if self.position_sigma_m is not None:
                row["position_sigma_m"] = float(self.position_sigma_m[i])
            rows.append(row)
        return rows

    @staticmethod
    def concat(records: list[EvalRecord]) -> EvalRecord:
        """Rows of several records of the same sample, in order."""
        if not records:
            raise ValueError("EvalRecord.concat: no records")
        r0 = records[0]

        def cat(attr):
            return np.concatenate([getattr(r, attr) for r in records])

        grad = [r.loss_t for r in records if r.loss_t is not None]
        if grad and len(grad) != len(records):
            raise ValueError("EvalRecord.concat: records of both modes (some differentiable, some not)")

        def cat_sigma(attr, shape):
            if all(getattr(r, attr) is None for r in records):
                return None
            return np.concatenate([np.full((len(r), *shape), np.nan) if getattr(r, attr) is None else getattr(r, attr)
                                   for r in records])

        return EvalRecord(
            r0.sample_id, r0.names, cat("theta"), cat("loss"), cat("error_m"), cat("position"), cat("conf"),
            cat("keypoints"), cat("reproj_error_px"), sum((r.reason for r in records), ()),
            sum((r.detail for r in records), ()), r0.penalty_m, torch.cat(grad) if grad else None,
            cat_sigma("keypoint_sigma", (4, 2)), cat_sigma("position_sigma_m", ()),
        )


@runtime_checkable
class SearchObjective(Protocol):
    """What a campaign runs a search on: a batched function of θ over ``box`` (the black box for a NumPy θ, the
    differentiable path for a torch θ), evaluated in chunks of ``batch_size`` on ``device``; ``evaluate`` gives the
    full record of θ rows; ``image_error`` says why the pixels could not be loaded (a failed sample, not a breach).
    :class:`Objective` (one image) and :class:`~vbl_robust.sequences.objective.SequenceObjective` (an approach) implement it."""

    box: ParameterBox
    batch_size: int

    @property
    def device(self) -> torch.device: ...

    @property
    def image_error(self) -> str: ...

    def __call__(self, theta: Any) -> Evaluations: ...

    def evaluate(self, theta: Any) -> Any: ...


class Objective:
    """``L(θ)`` for one sample: ``objective(theta (N, d)) -> Evaluations`` (metres and failure reasons; a torch θ
    gives values differentiable w.r.t. it).

    Args:
        sample: the :class:`~vbl_robust.data.sample.Sample` (its pixels are loaded on the first evaluation).
        detector: any :class:`~vbl_robust.detect.base.Detector` (``differentiable = True`` for a torch θ).
        box: the :class:`~vbl_robust.space.ParameterBox` whose names select the perturbations.
        pnp: PnP solver name (``"ippe_lm"`` default, ``"iterative"``, ``"sqpnp"``, ``"ippe"``).
        conf_threshold: τ_conf of σ_select.
        penalty_m: error assigned to any failure, metres.
        batch_size: θ rows per detector call (bounds memory).
        resolution: ``"auto"`` (resize to the detector's ``input_size`` when smaller than the image), ``"full"``,
            or an int long side in pixels.
        pnp_grad: gradient of the differentiable PnP layer (``"exact"`` or ``"bpnp"``).
        device: where the perturbation, the views and the differentiable PnP run (``auto``, ``cpu``,
            ``cuda[:N]``; :mod:`vbl_robust.detect.device`); None → the detector's ``device`` (CPU if it has none).
            θ, the losses and the black-box PnP stay on the CPU.
        max_reproj_px: a runtime monitor: a pose whose PnP reprojection residual (RMS, the sample's pixels) is above
            it is a flagged failure (``"monitor_rejected"``) instead of a pose; None: no monitor.
        max_sigma_m: a runtime monitor of a detector that says how sure it is (corner σ, a YOLO26-pose network): a
            pose whose corners' σ propagated through PnP (:attr:`EvalRecord.position_sigma_m`, metres) is above it
            is a flagged failure (``"monitor_rejected"``); None: no monitor. Black-box path only.

    Raises:
        ValueError: a user mistake (unknown parameter name, unknown PnP solver, bad threshold/penalty/batch size,
            a detector without ``detect``). An image that cannot be loaded is not the pipeline's failure: an
            evaluation then raises :class:`~vbl_robust.constants.NotMeasuredError` (``INPUT_UNAVAILABLE``).

    >>> import vbl_robust as vr                                     # doctest: +SKIP
    >>> objective = vr.Objective(sample, vr.OracleDetector(), box)  # doctest: +SKIP
    >>> objective(np.array([[10.0, 1.2]])).values                   # doctest: +SKIP
    array([3.1e-07])
    """

    def __init__(
        self,
        sample: Sample,
        detector: Detector,
        box: ParameterBox,
        pnp: str = "ippe_lm",
        *,
        conf_threshold: float = CONF_THRESHOLD,
        penalty_m: float = PENALTY_M,
        batch_size: int = 32,
        resolution: str | int = "auto",
        pnp_grad: str = "exact",
        device: str | None = None,
        max_reproj_px: float | None = None,
        max_sigma_m: float | None = None,
    ):
        if not isinstance(box, ParameterBox):
            raise ValueError(f"Objective: box must be a vbl_robust.ParameterBox, got {type(box).__name__}")
        if not isinstance(sample, Sample):
            raise ValueError(f"Objective: sample must be a vbl_robust.Sample, got {type(sample).__name__}")
        if not callable(getattr(detector, "detect", None)):
            raise ValueError(f"Objective: detector {detector_name(detector)} has no detect(context) method")
        if pnp not in SOLVERS:
            raise ValueError(f"Objective: unknown PnP solver pnp={pnp!r}; choose from {SOLVERS}")
        if not (0.0 <= float(conf_threshold) <= 1.0):
            raise ValueError(f"Objective: conf_threshold must be in [0, 1], got {conf_threshold}")
        if not (np.isfinite(penalty_m) and penalty_m >= 0):  # 0: flagged failures count as safe (misleading only)
            raise ValueError(f"Objective: penalty_m must be finite and >= 0, got {penalty_m}")
        if max_reproj_px is not None and not (np.isfinite(max_reproj_px) and max_reproj_px > 0):
            raise ValueError(f"Objective: max_reproj_px must be a finite number > 0, got {max_reproj_px}")
        if max_sigma_m is not None and not (np.isfinite(max_sigma_m) and max_sigma_m > 0):
            raise ValueError(f"Objective: max_sigma_m must be a finite number > 0, got {max_sigma_m}")
        if isinstance(batch_size, bool) or not isinstance(batch_size, int | np.integer) or batch_size < 1:
            raise ValueError(f"Objective: batch_size must be an int >= 1, got {batch_size!r}")
        if resolution not in ("auto", "full") and not (isinstance(resolution, int | np.integer) and resolution >= 8):
            raise ValueError(f"Objective: resolution must be 'auto', 'full' or an int >= 8, got {resolution!r}")
        self.sample = sample
        self.detector = detector
        self.box = box
        self.perturbation = Perturbation(box)  # ValueError naming unknown parameters
        self.pnp = pnp
        self.conf_threshold = float(conf_threshold)
        self.penalty_m = float(penalty_m)
        self.max_reproj_px = None if max_reproj_px is None else float(max_reproj_px)
        self.max_sigma_m = None if max_sigma_m is None else float(max_sigma_m)
        self.batch_size = int(batch_size)
        self.resolution = resolution
        self.pnp_grad = pnp_grad
        from .detect.device import resolve_device

        # where the views are made: the detector's device unless told (a mismatch works, at a transfer per batch)
        self.device = torch.device(resolve_device(device if device is not None else
                                                  str(getattr(detector, "device", "cpu"))))
        self.nfev = 0
        self._loaded = False
        self._image_error = ""
        self._base: np.ndarray | None = None
        self._base_t: torch.Tensor | None = None
        self._scale = PixelScale()

    def __repr__(self) -> str:
        return f"Objective(sample={self.sample.id!r}, detector={self.detector!r}, box={self.box!r}, pnp={self.pnp!r})"

    @property
    def names(self) -> tuple[str, ...]:
        return self.box.names

    @property
    def dim(self) -> int:
        return self.box.dim

    # -- pixels ------------------------------------------------------------------------------------------------
    def _long_side(self) -> int | None:
        if self.resolution == "full":
            return None
        if self.resolution == "auto":
            size = getattr(self.detector, "input_size", None)
            return int(size) if size else None
        return int(self.resolution)

    def _load(self) -> None:
        """Load and resize the pixels once; a failure is recorded (:attr:`image_error`; an evaluation then raises
        :class:`~vbl_robust.constants.NotMeasuredError`)."""
        if self._loaded:
            return
        self._loaded = True
        s = self.sample
        try:
            img = np.asarray(s.image)
            if img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"sample {s.id}: image must be (H, W, 3) RGB, got shape {img.shape}")
        except (OSError, ValueError) as e:  # FileNotFoundError is an OSError
            # the file by the sample's name (a LARD sample's id is its path inside the dataset), never the absolute path
            self._image_error = str(e).replace(str(s.image_path), str(s.id)) if s.image_path else str(e)
            logger.warning("sample %s: pixels unavailable, the sample cannot be measured: %s", s.id, self._image_error)
            return
        self._scale, size = PixelScale.for_long_side(s.width, s.height, self._long_side())
        base = img.astype(np.float32) / 255.0 if img.dtype == np.uint8 else img.astype(np.float32)
        self._base = np.ascontiguousarray(resize_image(base, size))
        self._base_t = torch.from_numpy(self._base).permute(2, 0, 1).to(self.device)

    @property
    def scale(self) -> PixelScale:
        """Mapping from the sample's pixels to the pixels the detector receives."""
        self._load()
        return self._scale

    @property
    def image_error(self) -> str:
        """Why the pixels could not be loaded (``""`` if they could)."""
        self._load()
        return self._image_error

    def context(self, theta) -> DetectContext:
        """The :class:`~vbl_robust.detect.base.DetectContext` of θ rows ``(B, d)`` (NumPy or a tensor)."""
        self._load()
        sampler = ViewSampler(self.perturbation, self._base_t, theta, self._scale.to_scaled(self.sample.K[:2, 2]),
                              K=self._scale.intrinsics(self.sample.K), scale=self._scale, frame=self._base)
        return DetectContext(self.sample, sampler, self._scale)

    # -- the contract: θ → Evaluations / EvalRecord (module docstring) -------------------------------------------
    def __call__(self, theta) -> Evaluations:
        """``theta (N, d)`` real units → :class:`~vbl_robust.search.evaluations.Evaluations`: ``L`` in metres (float64; a tensor
        differentiable w.r.t. a torch θ) and the failure reason per row."""
        return self.evaluate(theta).evaluations()

    def evaluate(self, theta) -> EvalRecord:
        """Like ``__call__`` with every detail per row (positions, confidences, keypoints, failure reasons).

        A torch θ takes the differentiable path: gradients flow through the view sampler, the detector's
        ``detect_top`` and the implicit PnP gradient into :attr:`EvalRecord.loss_t`; penalised rows are the constant
        ``penalty_m`` with zero gradient (never NaN).
        """
        if isinstance(theta, torch.Tensor):
            self.check_differentiable()
            t = self.perturbation.check_theta(theta)
        else:
            try:
                t = np.asarray(theta, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"theta must be numbers, shape (N, {self.dim}) for parameters {self.names}; "
                                 f"got {theta!r}"[:300]) from None
            t = self.perturbation.check_theta(t)
        self._load()
        self.nfev += t.shape[0]
        if self._image_error:  # the tool's failure, not the pipeline's: no value at all
            err, sid = self._image_error, str(self.sample.id)
            raise NotMeasuredError(NotMeasured.INPUT_UNAVAILABLE, err if sid in err else f"sample {sid}: {err}")
        if t.shape[0] == 0:
            rec = self._all_failed(t, "", "")
        else:
            parts = [self.locate(c, self.select_at(c)) for c in (t[i : i + self.batch_size]
                                                                  for i in range(0, t.shape[0], self.batch_size))]
            rec = parts[0] if len(parts) == 1 else EvalRecord.concat(parts)
        if rec.loss_t is not None:  # keeps the result attached to θ even if every row failed
            rec = dataclasses.replace(rec, loss_t=rec.loss_t + 0.0 * t.sum(dim=1).to(torch.float64))
        return rec

    def check_differentiable(self) -> None:
        """``ValueError`` unless the detector has the differentiable path (``detect_top``) a torch θ needs."""
        if not getattr(self.detector, "differentiable", False) or not callable(getattr(self.detector, "detect_top",
                                                                                      None)):
            why = getattr(self.detector, "gradient_unavailable", "") or "no detect_top"
            raise NotMeasuredError(NotMeasured.METHOD_UNFIT,
                                   f"a gradient search cannot run: the detector {detector_name(self.detector)} is not "
                                   f"differentiable ({why}); it supports only the black-box path (a NumPy theta)")
        if self.max_sigma_m is not None:
            raise NotMeasuredError(NotMeasured.METHOD_UNFIT, "the σ monitor (max_sigma_m) reads the black-box path; "
                                   "a gradient search (a torch theta) cannot run under it")

    # -- the two steps of a chunk ----------------------------------------------------------------------------------
    def select_at(self, theta) -> Selection:
        """Step 1: one detector call on the views of θ rows ``(B, d)`` and σ_select (:meth:`selection`)."""
        ctx = self.context(theta)
        if isinstance(theta, torch.Tensor):
            return self.selection(self.detector.detect_top(ctx), int(theta.shape[0]))
        with torch.no_grad():
            return self.selection(self.detector.detect(ctx), int(theta.shape[0]))

    def selection(self, raw, n: int) -> Selection:
        """σ_select of a detector's output for ``n`` rows — a list of ``Detections`` (the detector's ``detect``) or the top
        candidates ``(conf (n,), keypoints (n, 4, 2))`` of ``detect_top`` (then ``keypoints_t`` is set) — with the
        keypoints in the sample's pixels."""
        if isinstance(raw, tuple):
            conf_t, kp_t = raw
            kp_t = self._scale.to_original(kp_t.reshape(n, 4, 2).to(torch.float64))
            conf = conf_t.detach().reshape(-1).cpu().numpy().astype(np.float64)
            ok = conf >= self.conf_threshold
            return Selection(kp_t.detach().cpu().numpy(), conf, ok,
                             tuple("" if good else FailureReason.LOW_CONFIDENCE for good in ok), kp_t)
        dets = list(raw)
        if len(dets) != n:
            raise ValueError(f"Objective: detector {detector_name(self.detector)} returned {len(dets)} results for {n} "
                             "images")
        sel = select(dets, self.conf_threshold)
        sigma = sel.sigma / np.array([self._scale.sx, self._scale.sy]) if sel.sigma is not None else None
        return dataclasses.replace(sel, keypoints=self._scale.to_original(sel.keypoints), sigma=sigma)

    def locate(self, theta, sel: Selection) -> EvalRecord:
        """Step 2: PnP on the selected keypoints and the position error of θ rows ``(B, d)`` → :class:`EvalRecord`
        (with ``loss_t`` when ``sel`` came from the differentiable path)."""
        grad = sel.keypoints_t is not None
        n = int(theta.shape[0])
        kp, conf, reason = sel.keypoints, sel.conf, list(sel.reason)
        finite_kp = np.isfinite(kp).all(axis=(1, 2))
        for i in np.nonzero((np.array(reason) == "") & ~finite_kp)[0]:
            reason[i] = FailureReason.NON_FINITE_KEYPOINTS
        rows = np.nonzero(np.array([r == "" for r in reason]))[0]
        position, reproj = np.full((n, 3), np.nan), np.full(n, np.nan)
        error, detail = np.full(n, np.nan), [""] * n
        y = self.sample.position
        if rows.size and grad:
            pos_t, ok_t = pnp_position_torch(sel.keypoints_t[rows], self.sample.corners_3d, self.sample.K,
                                             method=self.pnp, grad=self.pnp_grad)
            position[rows] = pos_t.detach().cpu().numpy()
            success = ok_t.cpu().numpy()
        elif rows.size:
            res = solve(kp[rows], self.sample.corners_3d, self.sample.K, method=self.pnp)
            position[rows], reproj[rows], success = res.position, res.reproj_error_px, res.success
            for j, i in enumerate(rows):
                detail[i] = "" if success[j] else res.reason[j]
        err = np.linalg.norm(position[rows] - y, axis=1)
        if self.max_reproj_px is not None and rows.size and grad:  # the monitor reads the residual of the forward
            reproj[rows] = solve(kp[rows], self.sample.corners_3d, self.sample.K, method=self.pnp).reproj_error_px
        kp_sigma = pos_sigma = None
        if sel.sigma is not None and np.isfinite(sel.sigma).any():  # the detector says how sure it is
            kp_sigma, pos_sigma = sel.sigma, np.full(n, np.nan)
            if rows.size:
                pos_sigma[rows] = position_sigma(kp[rows], kp_sigma[rows], self.sample.corners_3d, self.sample.K,
                                                 method=self.pnp)
        elif self.max_sigma_m is not None and rows.size:
            raise ValueError(f"Objective: the σ monitor (max_sigma_m) needs a detector that gives its corners' σ "
                             f"(a YOLO26-pose network); {detector_name(self.detector)} gives none")
        for j, i in enumerate(rows):
            if not success[j]:
                reason[i] = FailureReason.PNP_FAILED
            elif not np.isfinite(err[j]):
                reason[i] = FailureReason.NON_FINITE_POSITION
            elif self.max_reproj_px is not None and not reproj[i] <= self.max_reproj_px:
                reason[i] = FailureReason.MONITOR_REJECTED  # the monitor flags the pose: the system knows it has no fix
            elif self.max_sigma_m is not None and not pos_sigma[i] <= self.max_sigma_m:
                reason[i] = FailureReason.MONITOR_REJECTED
            else:
                error[i] = err[j]
        failed = np.array([r != "" for r in reason])
        error[failed] = np.nan
        theta_np = theta.detach().cpu().numpy().astype(np.float64) if isinstance(theta, torch.Tensor) else theta
        loss_t = None
        if grad:
            loss_t = torch.full((n,), self.penalty_m, dtype=torch.float64, device=theta.device)
            good = np.nonzero(~failed[rows])[0] if rows.size else np.zeros(0, dtype=int)
            if good.size:  # the loss lives with θ (the CPU for APGD), whatever device ran the pipeline
                yt = torch.as_tensor(y, dtype=torch.float64, device=theta.device)
                err_t = torch.linalg.vector_norm(pos_t[good].to(theta.device) - yt, dim=1)
                loss_t = loss_t.index_put((torch.as_tensor(rows[good], device=theta.device),), err_t)
        return EvalRecord(str(self.sample.id), self.names, theta_np, np.where(failed, self.penalty_m, error), error,
                          position, conf, kp, reproj, tuple(reason), tuple(detail), self.penalty_m, loss_t,
                          kp_sigma, pos_sigma)

    def _all_failed(self, t, reason: str, detail: str) -> EvalRecord:  # an empty θ batch
        n = t.shape[0]
        nan = np.full(n, np.nan)
        grad = isinstance(t, torch.Tensor)
        return EvalRecord(
            str(self.sample.id), self.names, t.detach().cpu().numpy().astype(np.float64) if grad else t,
            np.full(n, self.penalty_m), nan, np.full((n, 3), np.nan), nan.copy(), np.full((n, 4, 2), np.nan),
            nan.copy(), (reason,) * n, (detail,) * n, self.penalty_m,
            torch.full((n,), self.penalty_m, dtype=torch.float64) if grad else None,
        )


def detector_name(detector: Any) -> str:
    """A detector as a user names it in one line: its file name, else its class name (never a Python repr)."""
    path = getattr(detector, "path", None)
    name = getattr(path, "name", None) or (str(path).rsplit("/", 1)[-1] if path else "")
    kind = type(detector).__name__
    return f"{name} ({kind})" if name else kind
