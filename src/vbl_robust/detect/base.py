"""The detector protocol, candidate containers and the selection σ_select.

What a detector is (for adapter writers)
----------------------------------------
Any object with

* ``input_size: int | None`` (optional, default ``None``) — the long side, in pixels, of the view the detector resamples its input to (e.g.
  640 for a YOLOv8-Pose letterboxed to 640 × 640), or ``None`` if it uses images at any size as given. The
  :class:`~vbl_robust.pipeline.Objective` uses it to perturb images at that resolution instead of the full one
  (rotation about the principal point commutes with isotropic scaling), so the detector then receives images
  whose long side is ``input_size``. Adapters must accept any size anyway.
* ``detect(images, *, context=None) -> list[Detections]`` — the **black-box path**: ``images`` is a
  ``(B, 3, H, W)`` float tensor, RGB in ``[0, 1]``; called under ``torch.no_grad()``. Returns one
  :class:`Detections` per image, all candidates the detector reports (after its own NMS), in the pixel
  coordinates **of the images passed in** (OpenCV convention: ``u`` right, ``v`` down, pixel centres at
  integers) — an adapter undoes its own letterbox/resize. Keypoints in the order TR, TL, BL, BR.
* optionally ``detect_top(images, *, context=None) -> (conf (B,), keypoints (B, 4, 2))`` — the
  **differentiable path** (:class:`DifferentiableDetector`): the single candidate of maximum confidence per
  image, as tensors with gradients flowing back to ``images`` (raw predictions before NMS, argmax + ``gather``).
  Same coordinates as ``detect``. A confidence below the threshold (e.g. 0 when there is no candidate at all)
  makes the row a failure. Its top candidate should equal ``select(detect(images))`` (same network outputs).

* optionally ``uses_pixels: bool`` (default True) — ``False`` declares that the detector reads only the
  ``context``, never the pixels (the oracle); the Objective then skips perturbing the images and passes the
  unperturbed image broadcast over the batch.

``context`` (a :class:`DetectContext`) tells the detector which sample and which θ produced the images. Real
detectors ignore it (a ``detect``/``detect_top`` without a ``context`` parameter is called without it); the :class:`~vbl_robust.detect.oracle.OracleDetector` uses it to return the ground-truth
corners moved by the same perturbation. The pipeline always passes it; direct callers may pass ``None``.

Selection (the paper's σ_select)
--------------------------------
:func:`select` keeps, per image, the candidate of maximum confidence if that confidence is ``≥ τ_conf``
(default 0.25), else the image is a failure (``no_detection`` or ``low_confidence``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
import torch

from vbl_robust.perturb import Perturbation, PixelScale

if TYPE_CHECKING:
    from vbl_robust.data.sample import Sample

__all__ = [
    "DEFAULT_CONF_THRESHOLD",
    "DetectContext",
    "Detections",
    "Detector",
    "DifferentiableDetector",
    "Selection",
    "select",
]

#: The paper's operational confidence threshold τ_conf.
DEFAULT_CONF_THRESHOLD = 0.25


def _np(a, dtype=np.float64) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        a = a.detach().cpu().numpy()
    return np.asarray(a, dtype=dtype)


@dataclass(eq=False)
class Detections:
    """All candidates of one image (NumPy, float64; tensors are converted).

    Attributes:
        boxes: ``(M, 4)`` boxes ``x1, y1, x2, y2``, pixels of the image given to the detector.
        conf: ``(M,)`` confidences in ``[0, 1]``.
        keypoints: ``(M, 4, 2)`` corners TR, TL, BL, BR, same pixels as ``boxes``.
        keypoint_conf: optional ``(M, 4)`` per-keypoint visibility/confidence.
    """

    boxes: np.ndarray
    conf: np.ndarray
    keypoints: np.ndarray
    keypoint_conf: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.conf = _np(self.conf).reshape(-1)
        m = self.conf.shape[0]
        self.boxes = _np(self.boxes).reshape(m, 4)
        self.keypoints = _np(self.keypoints).reshape(m, 4, 2)
        if self.keypoint_conf is not None:
            self.keypoint_conf = _np(self.keypoint_conf).reshape(m, 4)

    def __len__(self) -> int:
        return int(self.conf.shape[0])

    @classmethod
    def empty(cls) -> Detections:
        """No candidate at all."""
        return cls(np.zeros((0, 4)), np.zeros(0), np.zeros((0, 4, 2)))


@dataclass(frozen=True, eq=False)
class DetectContext:
    """What produced a batch of images: the sample, the θ rows and the perturbation, and the resolution.

    Attributes:
        sample: the :class:`~vbl_robust.data.sample.Sample` the images were made from.
        theta: ``(B, d)`` parameters in real units, one row per image (NumPy, or a tensor on the
            differentiable path), columns named by ``perturbation.names``.
        perturbation: the :class:`~vbl_robust.perturb.Perturbation` applied.
        scale: mapping from the sample's pixels to the pixels of the images given to the detector.
        perturbed: True when the images already show ``T(x; θ)``; False when the caller handed the *unperturbed*
            image (every row) to a detector whose ``applies_perturbation(perturbation)`` is true — that detector
            then applies θ itself while sampling its views (e.g. :class:`~vbl_robust.detect.TwoStageDetector`).
    """

    sample: Sample
    theta: np.ndarray | torch.Tensor
    perturbation: Perturbation
    scale: PixelScale = PixelScale()
    perturbed: bool = True

    @property
    def center(self) -> np.ndarray:
        """Rotation centre (the principal point of ``sample.K``) in the detector-input pixels, ``(2,)``."""
        return self.scale.to_scaled(self.sample.K[:2, 2])

    def move_points(self, points):
        """Sample pixels ``(P, 2)`` → where the perturbation moves them, in detector-input pixels ``(B, P, 2)``.

        A tensor θ gives a tensor differentiable w.r.t. θ.
        """
        return self.perturbation.points(self.scale.to_scaled(np.asarray(points, np.float64)), self.theta,
                                        center=self.center)


@runtime_checkable
class Detector(Protocol):
    """Black-box runway-corner detector (see the module docstring for the full contract)."""

    input_size: int | None

    def detect(self, images: torch.Tensor, *, context: DetectContext | None = None) -> list[Detections]:
        """``(B, 3, H, W)`` float RGB in [0, 1] → one :class:`Detections` per image (input-image pixels)."""
        ...


@runtime_checkable
class DifferentiableDetector(Detector, Protocol):
    """A :class:`Detector` that also has the differentiable max-confidence path."""

    def detect_top(
        self, images: torch.Tensor, *, context: DetectContext | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(B, 3, H, W)`` → ``(conf (B,), keypoints (B, 4, 2))`` of the top candidate, differentiable."""
        ...


@dataclass(frozen=True, eq=False)
class Selection:
    """Result of σ_select over a batch.

    Attributes:
        keypoints: ``(B, 4, 2)`` keypoints of the selected candidate (NaN where ``ok`` is False).
        conf: ``(B,)`` maximum confidence per image (NaN when the image has no candidate).
        ok: ``(B,)`` True when a candidate with ``conf ≥ τ_conf`` was selected.
        reason: ``B`` strings: ``""``, ``"no_detection"`` or ``"low_confidence"``.
    """

    keypoints: np.ndarray
    conf: np.ndarray
    ok: np.ndarray
    reason: tuple[str, ...]


def select(detections: Sequence[Detections] | Detections, conf_threshold: float = DEFAULT_CONF_THRESHOLD) -> Selection:
    """σ_select: per image, the candidate of maximum confidence if ``conf ≥ conf_threshold``, else a failure.

    Ties go to the first candidate. A single :class:`Detections` is treated as a batch of one.

    >>> d = Detections(np.zeros((2, 4)), np.array([0.3, 0.9]), np.stack([np.zeros((4, 2)), np.ones((4, 2))]))
    >>> s = select([d, Detections.empty()])
    >>> s.ok.tolist(), s.reason, s.keypoints[0, 0].tolist()
    ([True, False], ('', 'no_detection'), [1.0, 1.0])
    """
    if not (0.0 <= float(conf_threshold) <= 1.0):
        raise ValueError(f"select: conf_threshold must be in [0, 1], got {conf_threshold}")
    if isinstance(detections, Detections):
        detections = [detections]
    b = len(detections)
    kp = np.full((b, 4, 2), np.nan)
    conf = np.full(b, np.nan)
    ok = np.zeros(b, dtype=bool)
    reason = []
    for i, d in enumerate(detections):
        if len(d) == 0:
            reason.append("no_detection")
            continue
        dc = _np(d.conf).reshape(-1)  # tolerate tensors from detectors with their own containers
        c = np.where(np.isfinite(dc), dc, -np.inf)
        m = int(np.argmax(c))
        conf[i] = dc[m]
        if not conf[i] >= conf_threshold:
            reason.append("low_confidence")
            continue
        kp[i] = _np(d.keypoints)[m]
        ok[i] = True
        reason.append("")
    return Selection(kp, conf, ok, tuple(reason))
