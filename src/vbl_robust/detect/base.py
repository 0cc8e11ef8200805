"""The detector protocol, candidate containers and the selection σ_select.

What a detector is (for adapter writers)
----------------------------------------
A class with three declared capabilities and one required method (a fourth capability is optional)::

    class MyDetector:
        input_size: int | None = 640      # long side of the source it wants (None: full resolution)
        uses_pixels: bool = True          # False: reads only the context (the oracle)
        differentiable: bool = False      # True: also has detect_top (white-box searches)
        gives_sigma: bool = False         # True: its Detections carry keypoint_sigma (the σ monitor can run)

        def detect(self, context: DetectContext) -> list[Detections]: ...
        def detect_top(self, context: DetectContext) -> tuple[Tensor, Tensor]: ...   # if differentiable

* ``input_size`` — the :class:`~vbl_robust.pipeline.Objective` resizes the sample's image so that its long side is
  ``input_size`` before the perturbation is applied (rotation about the principal point commutes with isotropic
  scaling), so a detector that letterboxes to 640 × 640 never receives pixels it would throw away.
* ``detect(context)`` — the **black-box path**, called under ``torch.no_grad()``. The detector asks the context
  for what it needs: ``context.views(windows, size)`` (square views of the perturbed images, see
  :mod:`vbl_robust.perturb.views`), ``context.frames()`` (the whole perturbed images), or, for the oracle,
  ``context.move_points(points)``. It returns one :class:`Detections` per row of ``context.theta``: all
  candidates after its own NMS, in the pixel coordinates of the context's source (OpenCV convention: ``u``
  right, ``v`` down, pixel centres at integers), keypoints in the order TR, TL, BL, BR.
* ``detect_top(context)`` — the **differentiable path**: ``(conf (B,), keypoints (B, 4, 2))`` of the candidate
  of maximum confidence per row (raw predictions before NMS, argmax + ``gather``), with gradients flowing back
  to θ. A confidence below the threshold (0 when there is no candidate) makes the row a failure. Its top
  candidate equals ``select(detect(context))`` (same network outputs).

Capabilities are class attributes, read as they are declared (never guessed from signatures).
:func:`DetectContext.of_images` wraps plain images (no perturbation) for direct calls.

Selection (the paper's σ_select)
--------------------------------
:func:`select` keeps, per image, the candidate of maximum confidence if that confidence is ``≥ τ_conf``
(:data:`vbl_robust.constants.CONF_THRESHOLD` = 0.25), else the image is a failure (``no_detection`` or
``low_confidence``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
import torch

from vbl_robust.constants import CONF_THRESHOLD, FailureReason
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.resample import PixelScale
from vbl_robust.perturb.views import ViewSampler, to_tensor

if TYPE_CHECKING:
    from vbl_robust.data.sample import Sample

__all__ = [
    "DetectContext",
    "Detections",
    "ImageViews",
    "as_context",
    "Detector",
    "DifferentiableDetector",
    "Selection",
    "select",
]


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
        keypoint_sigma: optional ``(M, 4, 2)`` per-corner uncertainty σ_u, σ_v (same pixels as ``keypoints``), from a
            network with an uncertainty head (YOLO26-pose); None: the detector does not say how sure it is.
        reason: for an image without candidates, why (a code of :data:`vbl_robust.constants.FAILURE_REASONS`,
            e.g. ``"out_of_view"``); ``""`` = :func:`select` reports ``"no_detection"``.
    """

    boxes: np.ndarray
    conf: np.ndarray
    keypoints: np.ndarray
    keypoint_conf: np.ndarray | None = None
    keypoint_sigma: np.ndarray | None = None
    reason: str = ""

    def __post_init__(self) -> None:
        self.conf = _np(self.conf).reshape(-1)
        m = self.conf.shape[0]
        fields = [("boxes", (m, 4)), ("keypoints", (m, 4, 2))]
        if self.keypoint_conf is not None:
            fields.append(("keypoint_conf", (m, 4)))
        if self.keypoint_sigma is not None:
            fields.append(("keypoint_sigma", (m, 4, 2)))
        for name, shape in fields:
            value = _np(getattr(self, name))
            if value.size != int(np.prod(shape)):
                raise ValueError(f"Detections: {name} must have shape {shape} for {m} candidates, got {value.shape}")
            setattr(self, name, value.reshape(shape))

    def __len__(self) -> int:
        return int(self.conf.shape[0])

    @classmethod
    def empty(cls, reason: str = "") -> Detections:
        """No candidate at all (``reason``: why, when the detector knows; see :attr:`reason`)."""
        return cls(np.zeros((0, 4)), np.zeros(0), np.zeros((0, 4, 2)), reason=reason)


@runtime_checkable
class Views(Protocol):
    """What a detector reads a batch of perturbed images through (:attr:`DetectContext.sampler`): ``len`` rows of
    ``theta`` (None for plain images) under ``perturbation``, full frames, views of windows, and points moved by the
    perturbation. Implemented by :class:`~vbl_robust.perturb.views.ViewSampler`, :class:`ImageViews` and the sequence
    objective's stack of frames."""

    perturbation: Any
    theta: Any

    def __len__(self) -> int: ...

    @property
    def height(self) -> int: ...

    @property
    def width(self) -> int: ...

    @property
    def device(self) -> torch.device: ...

    def frames(self) -> torch.Tensor: ...

    def views(self, windows: Any, size: int) -> torch.Tensor: ...

    def points(self, points: Any) -> Any: ...


@dataclass(frozen=True, eq=False)
class DetectContext:
    """What a detector is asked about: a batch of perturbed images of one sample, given as a view sampler.

    Attributes:
        sample: the :class:`~vbl_robust.data.sample.Sample` (None for plain images, :meth:`of_images`).
        sampler: the :class:`Views` of ``T(x; θ)`` (a :class:`~vbl_robust.perturb.views.ViewSampler`, or
            :class:`ImageViews` for plain images).
        scale: mapping from the sample's pixels to the source pixels of the sampler.
    """

    sample: Sample | None
    sampler: Views
    scale: PixelScale = PixelScale()

    @classmethod
    def of_images(cls, images) -> DetectContext:
        """A context for plain images ``(B, 3, H, W)`` float in [0, 1] / ``(H, W, 3)`` or ``(B, H, W, 3)`` uint8
        (no sample, no perturbation): for calling a pixel detector directly."""
        return cls(None, ImageViews(to_tensor(images)))

    @classmethod
    def for_sample(cls, sample: Sample, perturbation: Perturbation, theta, scale: PixelScale = PixelScale(),
                   image=None) -> DetectContext:
        """The context of θ rows for ``sample``: its views sampled from ``image`` (the sample's pixels at ``scale``;
        None → a blank image, for detectors that read no pixels, such as the oracle). The sampler gets the
        sample's intrinsics at ``scale`` (:meth:`PixelScale.intrinsics
        <vbl_robust.perturb.resample.PixelScale.intrinsics>`: the attitude homography needs the focal length) and
        ``scale`` itself (blur lengths are in the sample's pixels)."""
        w, h = round(sample.width * scale.sx), round(sample.height * scale.sy)
        src = torch.zeros(1, 3, 1, 1).expand(1, 3, h, w) if image is None else image
        center = scale.to_scaled(np.asarray(sample.K, np.float64)[:2, 2])
        K = scale.intrinsics(sample.K)  # its principal point is `center`, bit for bit
        return cls(sample, ViewSampler(perturbation, src, theta, center, K=K, scale=scale), scale)

    @property
    def theta(self):
        """``(B, d)`` parameters in real units (NumPy, or a tensor on the differentiable path)."""
        return self.sampler.theta

    @property
    def perturbation(self) -> Perturbation | None:
        return self.sampler.perturbation

    def __len__(self) -> int:
        return len(self.sampler)

    @property
    def height(self) -> int:
        """Height of the source in pixels (the coordinates detections are given in)."""
        return self.sampler.height

    @property
    def width(self) -> int:
        return self.sampler.width

    @property
    def device(self) -> torch.device:
        """Where the views are made (the source image's device): detectors create their windows there."""
        return self.sampler.device

    def views(self, windows, size: int) -> torch.Tensor:
        """``(B, 3, size, size)`` views of the perturbed images (see :meth:`ViewSampler.views`)."""
        return self.sampler.views(windows, size)

    def frames(self) -> torch.Tensor:
        """``(B, 3, H, W)`` the whole perturbed images at the source resolution."""
        return self.sampler.frames()

    def move_points(self, points):
        """Sample pixels ``(P, 2)`` → where the perturbation moves them, in source pixels ``(B, P, 2)`` (a tensor θ
        gives a tensor differentiable w.r.t. θ)."""
        return self.sampler.points(self.scale.to_scaled(np.asarray(points, np.float64)))


class ImageViews:
    """The :class:`~vbl_robust.perturb.views.ViewSampler` interface over plain images ``(B, 3, H, W)`` (no perturbation)."""

    perturbation = None
    theta = None

    def __init__(self, images: torch.Tensor) -> None:
        self.images = images

    def __len__(self) -> int:
        return int(self.images.shape[0])

    @property
    def height(self) -> int:
        return int(self.images.shape[-2])

    @property
    def width(self) -> int:
        return int(self.images.shape[-1])

    @property
    def device(self) -> torch.device:
        return self.images.device

    def frames(self) -> torch.Tensor:
        return self.images

    def views(self, windows, size: int) -> torch.Tensor:
        from vbl_robust.perturb.views import resample

        return resample(self.images, windows, size)

    def points(self, points):
        raise ValueError("plain images carry no sample or perturbation: this detector needs a vr.Objective context")


def as_context(context_or_images) -> DetectContext:
    """A :class:`DetectContext` as it is, or plain images wrapped by :meth:`DetectContext.of_images`."""
    if isinstance(context_or_images, DetectContext):
        return context_or_images
    return DetectContext.of_images(context_or_images)


@runtime_checkable
class Detector(Protocol):
    """Runway-corner detector (see the module docstring for the full contract)."""

    input_size: int | None
    uses_pixels: bool
    differentiable: bool

    def detect(self, context: DetectContext) -> list[Detections]:
        """One :class:`Detections` per row of the context (source pixels)."""
        ...


@runtime_checkable
class DifferentiableDetector(Detector, Protocol):
    """A :class:`Detector` that also has the differentiable max-confidence path."""

    def detect_top(self, context: DetectContext) -> tuple[torch.Tensor, torch.Tensor]:
        """``(conf (B,), keypoints (B, 4, 2))`` of the top candidate, differentiable w.r.t. θ."""
        ...


@dataclass(frozen=True, eq=False)
class Selection:
    """Result of σ_select over a batch.

    Attributes:
        keypoints: ``(B, 4, 2)`` keypoints of the selected candidate (NaN where ``ok`` is False).
        conf: ``(B,)`` maximum confidence per image (NaN when the image has no candidate).
        ok: ``(B,)`` True when a candidate with ``conf ≥ τ_conf`` was selected.
        reason: ``B`` strings: ``""``, ``"no_detection"`` (or the reason an empty :class:`Detections` gives) or
            ``"low_confidence"``.
        keypoints_t: the differentiable path (``detect_top``): ``keypoints`` as a float64 tensor attached to θ;
            None otherwise.
        sigma: ``(B, 4, 2)`` the selected candidate's corner σ (:attr:`Detections.keypoint_sigma`); NaN where the
            detector gave none or nothing was selected; None on the differentiable path.
    """

    keypoints: np.ndarray
    conf: np.ndarray
    ok: np.ndarray
    reason: tuple[str, ...]
    keypoints_t: Any = None
    sigma: np.ndarray | None = None


def select(detections: Sequence[Detections] | Detections, conf_threshold: float = CONF_THRESHOLD) -> Selection:
    """σ_select: per image, the candidate of maximum confidence if ``conf ≥ conf_threshold``, else a failure.

    Ties go to the first candidate. A single :class:`Detections` is treated as a batch of one.

    >>> d = Detections(np.zeros((2, 4)), np.array([0.3, 0.9]), np.stack([np.zeros((4, 2)), np.ones((4, 2))]))
    >>> s = select([d, Detections.empty()])
    >>> s.ok.tolist(), [str(r) for r in s.reason], s.keypoints[0, 0].tolist()
    ([True, False], ['', 'no_detection'], [1.0, 1.0])
    """
    if not (0.0 <= float(conf_threshold) <= 1.0):
        raise ValueError(f"select: conf_threshold must be in [0, 1], got {conf_threshold}")
    if isinstance(detections, Detections):
        detections = [detections]
    b = len(detections)
    kp = np.full((b, 4, 2), np.nan)
    sigma = np.full((b, 4, 2), np.nan)
    conf = np.full(b, np.nan)
    ok = np.zeros(b, dtype=bool)
    reason = []
    for i, d in enumerate(detections):
        if len(d) == 0:
            reason.append(getattr(d, "reason", "") or FailureReason.NO_DETECTION)
            continue
        dc = _np(d.conf).reshape(-1)  # tolerate tensors from detectors with their own containers
        c = np.where(np.isfinite(dc), dc, -np.inf)
        m = int(np.argmax(c))
        conf[i] = dc[m]
        if not conf[i] >= conf_threshold:
            reason.append(FailureReason.LOW_CONFIDENCE)
            continue
        kp[i] = _np(d.keypoints)[m]
        if getattr(d, "keypoint_sigma", None) is not None:
            sigma[i] = _np(d.keypoint_sigma)[m]
        ok[i] = True
        reason.append("")
    return Selection(kp, conf, ok, tuple(reason), sigma=sigma)
