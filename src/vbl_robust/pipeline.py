"""The end-to-end error ``L(θ)`` of one sample: perturb → detect → select → PnP → position error.

For a sample (image ``x``, intrinsics ``K``, runway corners, true camera position ``y``) and a batch of
parameter vectors θ ``(N, d)`` in real units (columns named by the box)::

    x'  = T(x; θ)                     roll about the principal point, then contrast (vbl_robust.perturb)
    k   = σ_select(detector(x'))       max-confidence candidate if conf ≥ τ_conf (vbl_robust.detect)
    ŷ   = PnP(k, corners_3d, K)        camera position in the runway frame (vbl_robust.pnp)
    L   = ‖ŷ − y‖₂  (metres), or penalty_m (5000 m) on ANY failure

Failures (recorded per row in :class:`EvalRecord`): ``image_unavailable`` (the sample's pixels cannot be
loaded — every row, never an exception), ``no_detection``, ``low_confidence``, ``non_finite_keypoints``,
``pnp_failed``, ``non_finite_position``. A successful row is never capped: a wild but "successful" PnP can
exceed the penalty.

Resolution: images are perturbed at the detector's ``input_size`` (long side) when it is smaller than the
image — rotation about the principal point commutes with isotropic scaling, so this is the same perturbation,
computed on fewer pixels; the centre is mapped with :class:`~vbl_robust.perturb.PixelScale` and keypoints are
mapped back to the sample's pixels before PnP (``resolution="full"`` disables it).

A detector whose ``applies_perturbation(perturbation)`` is true (the two-stage detector) receives the
unperturbed image with a context marked ``perturbed=False`` and samples its views of ``T(x; θ)`` itself (no
full-resolution warp per evaluation; ``fuse=False`` disables it). A detector declaring ``uses_pixels = False``
(the oracle) receives the unperturbed image broadcast over the
batch instead of perturbed copies: it reads the perturbation from the context, and the audit runs fast.

Two paths: ``objective(theta)`` (NumPy, no gradient, OpenCV warps) and ``objective.torch(theta)``
(differentiable w.r.t. θ through kornia, the detector's ``detect_top`` and the implicit PnP gradient;
penalised rows are constant with zero gradient, never NaN).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import torch

from vbl_robust.data.sample import Sample
from vbl_robust.detect.base import DEFAULT_CONF_THRESHOLD, DetectContext, Detector, select
from vbl_robust.perturb import Perturbation, PixelScale, resize_image
from vbl_robust.pnp import SOLVERS, solve
from vbl_robust.space import ParameterBox

logger = logging.getLogger(__name__)

__all__ = ["DEFAULT_PENALTY_M", "FAILURE_REASONS", "EvalRecord", "Objective"]

#: Error assigned to any failure, metres (the paper's L_E2E for a detection breakdown).
DEFAULT_PENALTY_M = 5000.0

FAILURE_REASONS = (
    "image_unavailable",
    "no_detection",
    "low_confidence",
    "non_finite_keypoints",
    "pnp_failed",
    "non_finite_position",
)


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
    penalty_m: float = DEFAULT_PENALTY_M

    def __len__(self) -> int:
        return int(self.loss.shape[0])

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

        return EvalRecord(
            r0.sample_id, r0.names, cat("theta"), cat("loss"), cat("error_m"), cat("position"), cat("conf"),
            cat("keypoints"), cat("reproj_error_px"), sum((r.reason for r in records), ()),
            sum((r.detail for r in records), ()), r0.penalty_m,
        )


def _takes_context(fn) -> bool:
    """True when ``fn`` accepts a ``context`` keyword (or ``**kwargs``); detectors may omit it."""
    import inspect

    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return True
    return any(p.name == "context" or p.kind is inspect.Parameter.VAR_KEYWORD for p in params)


class Objective:
    """``L(θ)`` for one sample: ``objective(theta (N, d)) -> (N,)`` metres; ``objective.torch`` differentiable.

    Args:
        sample: the :class:`~vbl_robust.data.sample.Sample` (its pixels are loaded on the first evaluation).
        detector: any :class:`~vbl_robust.detect.Detector` (``detect_top`` is needed for :meth:`torch`).
        box: the :class:`~vbl_robust.space.ParameterBox` whose names select the perturbations.
        pnp: PnP solver name (``"ippe_lm"`` default, ``"iterative"``, ``"sqpnp"``, ``"ippe"``).
        conf_threshold: τ_conf of σ_select.
        penalty_m: error assigned to any failure, metres.
        batch_size: θ rows per detector call (bounds memory).
        resolution: ``"auto"`` (perturb at the detector's ``input_size`` when smaller than the image),
            ``"full"``, or an int long side in pixels.
        pnp_grad: gradient of the differentiable PnP layer (``"exact"`` or ``"bpnp"``).
        fuse: let a detector that can (``detector.applies_perturbation(perturbation)``, e.g. the two-stage
            detector) apply the perturbation while sampling its own views from the unperturbed image, instead of
            receiving perturbed full-resolution copies (False: always perturb the image first).

    Raises:
        ValueError: a user mistake (unknown parameter name, unknown PnP solver, bad threshold/penalty/batch size,
            a detector without ``detect``). An image that cannot be loaded is NOT an error: every row is
            penalised with reason ``image_unavailable``.

    >>> import vbl_robust as vr                                     # doctest: +SKIP
    >>> objective = vr.Objective(sample, vr.OracleDetector(), box)  # doctest: +SKIP
    >>> objective(np.array([[10.0, 1.2]]))                          # doctest: +SKIP
    array([3.1e-07])
    """

    def __init__(
        self,
        sample: Sample,
        detector: Detector,
        box: ParameterBox,
        pnp: str = "ippe_lm",
        *,
        conf_threshold: float = DEFAULT_CONF_THRESHOLD,
        penalty_m: float = DEFAULT_PENALTY_M,
        batch_size: int = 32,
        resolution: str | int = "auto",
        pnp_grad: str = "exact",
        fuse: bool = True,
    ):
        if not isinstance(box, ParameterBox):
            raise ValueError(f"Objective: box must be a vbl_robust.ParameterBox, got {type(box).__name__}")
        if not isinstance(sample, Sample):
            raise ValueError(f"Objective: sample must be a vbl_robust.Sample, got {type(sample).__name__}")
        if not callable(getattr(detector, "detect", None)):
            raise ValueError(f"Objective: detector {detector!r} has no detect(images, *, context) method")
        if pnp not in SOLVERS:
            raise ValueError(f"Objective: unknown PnP solver pnp={pnp!r}; choose from {SOLVERS}")
        if not (0.0 <= float(conf_threshold) <= 1.0):
            raise ValueError(f"Objective: conf_threshold must be in [0, 1], got {conf_threshold}")
        if not (np.isfinite(penalty_m) and penalty_m > 0):
            raise ValueError(f"Objective: penalty_m must be finite and > 0, got {penalty_m}")
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
        self.batch_size = int(batch_size)
        self.resolution = resolution
        self.pnp_grad = pnp_grad
        self.fuse = bool(fuse)
        applies = getattr(detector, "applies_perturbation", None)
        #: the detector applies the perturbation itself (it then gets the unperturbed image)
        self.fused = self.fuse and callable(applies) and bool(applies(self.perturbation))
        self._uses_pixels = bool(getattr(detector, "uses_pixels", True))
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
        """Load and resample the pixels once; a failure is recorded (``image_unavailable``), never raised."""
        if self._loaded:
            return
        self._loaded = True
        s = self.sample
        try:
            img = np.asarray(s.image)
            if img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"sample {s.id}: image must be (H, W, 3) RGB, got shape {img.shape}")
        except (OSError, ValueError) as e:  # FileNotFoundError is an OSError
            self._image_error = str(e)
            logger.warning("sample %s: pixels unavailable, every evaluation is penalised: %s", s.id, e)
            return
        self._scale, size = PixelScale.for_long_side(s.width, s.height, self._long_side())
        base = img.astype(np.float32) / 255.0 if img.dtype == np.uint8 else img.astype(np.float32)
        self._base = np.ascontiguousarray(resize_image(base, size))
        self._base_t = torch.from_numpy(self._base).permute(2, 0, 1)

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

    def _center(self) -> np.ndarray:
        return self._scale.to_scaled(self.sample.K[:2, 2])

    def _context(self, theta) -> DetectContext:
        return DetectContext(self.sample, theta, self.perturbation, self._scale, perturbed=not self.fused)

    # -- black-box path ------------------------------------------------------------------------------------------
    def __call__(self, theta) -> np.ndarray:
        """``theta (N, d)`` real units → ``L (N,)`` float64 metres."""
        return self.evaluate(theta).loss

    def evaluate(self, theta) -> EvalRecord:
        """Like ``__call__`` with every detail per row (positions, confidences, keypoints, failure reasons)."""
        t = self.perturbation.check_theta(np.asarray(theta, dtype=np.float64))
        self._load()
        self.nfev += t.shape[0]
        if self._image_error:
            return self._all_failed(t, "image_unavailable", self._image_error)
        records = [self._evaluate_chunk(t[i : i + self.batch_size]) for i in range(0, t.shape[0], self.batch_size)]
        if not records:
            return self._all_failed(t, "", "")
        return records[0] if len(records) == 1 else EvalRecord.concat(records)

    def _all_failed(self, t: np.ndarray, reason: str, detail: str) -> EvalRecord:
        n = t.shape[0]
        nan = np.full(n, np.nan)
        return EvalRecord(
            str(self.sample.id), self.names, t, np.full(n, self.penalty_m), nan, np.full((n, 3), np.nan), nan.copy(),
            np.full((n, 4, 2), np.nan), nan.copy(), (reason,) * n, (detail,) * n, self.penalty_m,
        )

    def _evaluate_chunk(self, t: np.ndarray) -> EvalRecord:
        n = t.shape[0]
        if self._uses_pixels and not self.fused:
            imgs = self.perturbation.images_numpy(self._base, t, center=self._center())
            x = torch.from_numpy(imgs).permute(0, 3, 1, 2)  # a (B, 3, H, W) view; detectors copy if they need to
        else:
            x = self._base_t[None].expand(n, -1, -1, -1)
        kw = {"context": self._context(t)} if self.fused or _takes_context(self.detector.detect) else {}
        with torch.no_grad():
            dets = self.detector.detect(x, **kw)
        if len(dets) != n:
            raise ValueError(f"Objective: detector {self.detector!r} returned {len(dets)} results for {n} images")
        sel = select(dets, self.conf_threshold)
        kp = self._scale.to_original(sel.keypoints)
        reason = list(sel.reason)
        detail = [""] * n
        finite_kp = np.isfinite(kp).all(axis=(1, 2))
        for i in np.nonzero(sel.ok & ~finite_kp)[0]:
            reason[i] = "non_finite_keypoints"
        rows = np.nonzero(sel.ok & finite_kp)[0]
        position = np.full((n, 3), np.nan)
        reproj = np.full(n, np.nan)
        error = np.full(n, np.nan)
        if rows.size:
            res = solve(kp[rows], self.sample.corners_3d, self.sample.K, method=self.pnp)
            position[rows] = res.position
            reproj[rows] = res.reproj_error_px
            err = np.linalg.norm(res.position - self.sample.position, axis=1)
            for j, i in enumerate(rows):
                if not res.success[j]:
                    reason[i], detail[i] = "pnp_failed", res.reason[j]
                elif not np.isfinite(err[j]):
                    reason[i] = "non_finite_position"
                else:
                    error[i] = err[j]
        failed = np.array([r != "" for r in reason])
        loss = np.where(failed, self.penalty_m, error)
        error[failed] = np.nan
        return EvalRecord(
            str(self.sample.id), self.names, t, loss, error, position, sel.conf, kp, reproj, tuple(reason),
            tuple(detail), self.penalty_m,
        )

    # -- differentiable path ---------------------------------------------------------------------------------------
    def torch(self, theta) -> torch.Tensor:
        """``theta (N, d)`` tensor → ``L (N,)`` float64 tensor, differentiable w.r.t. θ.

        Gradients flow through the perturbation, the detector's ``detect_top`` and the implicit PnP gradient.
        Penalised rows are the constant ``penalty_m`` with zero gradient (never NaN).
        """
        top = getattr(self.detector, "detect_top", None)
        if not callable(top):
            raise ValueError(
                f"Objective.torch: detector {self.detector!r} has no detect_top(images, *, context) method "
                "(it supports only the black-box path)"
            )
        t = theta if isinstance(theta, torch.Tensor) else torch.as_tensor(np.asarray(theta, dtype=np.float64))
        t = self.perturbation.check_theta(t)
        self._load()
        self.nfev += t.shape[0]
        # an exact-zero term keeps the result attached to θ even when every row is penalised
        anchor = 0.0 * t.sum(dim=1).to(torch.float64)
        loss = torch.full((t.shape[0],), self.penalty_m, dtype=torch.float64, device=t.device)
        if self._image_error or t.shape[0] == 0:
            return loss + anchor
        confs, kps = [], []
        center = self._center()
        for i in range(0, t.shape[0], self.batch_size):
            th = t[i : i + self.batch_size]
            if self._uses_pixels and not self.fused:
                imgs = self.perturbation.images_torch(self._base_t, th, center=center)
            else:
                imgs = self._base_t[None].expand(th.shape[0], -1, -1, -1)
            conf, kp = top(imgs, **({"context": self._context(th)} if self.fused or _takes_context(top) else {}))
            confs.append(conf.reshape(-1))
            kps.append(kp.reshape(-1, 4, 2))
        conf, kp = torch.cat(confs), self._scale.to_original(torch.cat(kps).to(torch.float64))
        rows = torch.nonzero((conf.detach() >= self.conf_threshold) & torch.isfinite(kp.detach()).all(dim=(1, 2)))[:, 0]
        err = self._pnp_error_torch(kp, rows)
        if err is not None:
            rows, err = err
            loss = loss.index_put((rows,), err)
        return loss + anchor

    def _pnp_error_torch(self, kp: torch.Tensor, rows: torch.Tensor):
        """Position errors of the rows whose PnP succeeds: ``(rows, err)`` or None.

        The PnP layer already gives failed rows a zero gradient; their NaN positions are swapped for a finite
        stand-in before the norm, whose backward would otherwise turn ``0 · NaN`` into NaN.
        """
        from vbl_robust.pnp import pnp_position_torch

        if rows.numel() == 0:
            return None
        y = torch.as_tensor(self.sample.position, dtype=torch.float64, device=kp.device)
        pos, ok = pnp_position_torch(kp[rows], self.sample.corners_3d, self.sample.K, method=self.pnp,
                                     grad=self.pnp_grad)
        good = ok & torch.isfinite(pos.detach()).all(dim=1)
        if not bool(good.any()):
            return None
        pos = torch.where(good[:, None], pos, y + 1.0)
        err = torch.linalg.vector_norm(pos - y, dim=1)
        return rows[good], err[good]
