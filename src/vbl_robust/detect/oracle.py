"""The oracle detector: the ground-truth corners moved by the perturbation — "a perfect detector".

It never asks for pixels: it reads the sample from the :class:`~vbl_robust.detect.base.DetectContext` and moves its
corners with the context's view sampler (the same point map the perturbation applies to the image), so the whole
pipeline (perturb → detect → select → PnP → error) can be tested and audited without a network. With a camera
rotation (roll, pitch, yaw: the homography ``K R K⁻¹`` about the optical centre) the moved corners are exactly the
corners the rotated camera would see, so with an exact PnP solver the position error stays ~0 over any rotation:
a departure from that is a solver failure. Photometric, optical and noise families move no corner.

A corner that the rotation puts behind the camera has no image (the sampler's point map gives NaN): the oracle
then reports no candidate with the reason ``"out_of_view"`` (black box) / confidence 0 (differentiable path).
"""

from __future__ import annotations

import logging
import zlib

import numpy as np
import torch

from vbl_robust.constants import FailureReason
from vbl_robust.geometry.camera import project

from .base import DetectContext, Detections

logger = logging.getLogger(__name__)

__all__ = ["OracleDetector"]

_CORNER_SOURCES = ("auto", "labels", "projected")


class OracleDetector:
    """Returns the sample's corners moved by the perturbation's point transform, confidence 1.

    Args:
        fail_outside: report no candidate (black box) / confidence 0 (differentiable path) when a moved corner
            leaves the image ``[0, W−1] × [0, H−1]`` (sample pixels).
        noise_px: standard deviation of Gaussian noise added to each corner coordinate, in sample pixels.
            By default the noise is **fixed per sample** (drawn from ``seed`` and the sample id), i.e. a
            systematic detector error in image coordinates that does not rotate with the image: ``L(θ)`` stays a
            deterministic, smooth function of θ (and is no longer roll-invariant).
        seed: seed of the noise.
        resample_noise: draw fresh noise on every call instead (a jittery detector; ``L`` becomes random, the
            draws are reproducible from ``seed`` and the call sequence).
        corners: ``"labels"`` (``sample.corners_2d``), ``"projected"`` (projection of ``sample.corners_3d`` with
            the true pose, needs ``sample.R``; exact even when labels are truncated integers, as in LARD), or
            ``"auto"`` (projected when ``sample.R`` is known, labels otherwise).

    Both paths need the ``context`` the :class:`~vbl_robust.pipeline.Objective` passes (a sample and θ). The
    differentiable path returns keypoints as a differentiable function of θ.
    """

    input_size: int | None = None
    #: The oracle never reads pixels (the Objective then never loads or resizes them for it).
    uses_pixels: bool = False
    differentiable: bool = True

    def __init__(
        self,
        fail_outside: bool = False,
        noise_px: float = 0.0,
        seed: int = 0,
        *,
        resample_noise: bool = False,
        corners: str = "auto",
    ):
        if not (np.isfinite(noise_px) and noise_px >= 0.0):
            raise ValueError(f"OracleDetector: noise_px must be finite and >= 0, got {noise_px}")
        if corners not in _CORNER_SOURCES:
            raise ValueError(f"OracleDetector: corners must be one of {_CORNER_SOURCES}, got {corners!r}")
        self.fail_outside = bool(fail_outside)
        self.noise_px = float(noise_px)
        self.seed = int(seed)
        self.resample_noise = bool(resample_noise)
        self.corners = corners
        self._rng = np.random.default_rng(self.seed)

    def __repr__(self) -> str:
        return (f"OracleDetector(fail_outside={self.fail_outside}, noise_px={self.noise_px}, seed={self.seed}, "
                f"resample_noise={self.resample_noise}, corners={self.corners!r})")

    # -- helpers ---------------------------------------------------------------------------------------------
    def true_corners(self, sample) -> np.ndarray:
        """The ground-truth corners ``(4, 2)`` in sample pixels (see ``corners``)."""
        use_projection = self.corners == "projected" or (self.corners == "auto" and sample.R is not None)
        if not use_projection:
            return sample.corners_2d
        if sample.R is None:
            raise ValueError(f"OracleDetector(corners='projected'): sample {sample.id} has no rotation R")
        return project(sample.corners_3d, sample.R, sample.position, sample.K)

    def _noise(self, context: DetectContext, n: int) -> np.ndarray:
        """``(n, 4, 2)`` offsets in detector-input pixels."""
        if self.noise_px == 0.0:
            return np.zeros((n, 4, 2))
        if self.resample_noise:
            e = self._rng.normal(0.0, self.noise_px, size=(n, 4, 2))
        else:
            rng = np.random.default_rng([self.seed, zlib.crc32(str(context.sample.id).encode())])
            e = np.broadcast_to(rng.normal(0.0, self.noise_px, size=(4, 2)), (n, 4, 2))
        return e * np.array([context.scale.sx, context.scale.sy])

    def _outside(self, context: DetectContext, kp_input: np.ndarray) -> np.ndarray:
        """``(n,)`` True where a corner lies outside the sample image."""
        kp = context.scale.to_original(kp_input)
        w, h = context.sample.width, context.sample.height
        inside = (kp[..., 0] >= 0) & (kp[..., 0] <= w - 1) & (kp[..., 1] >= 0) & (kp[..., 1] <= h - 1)
        return ~np.all(inside, axis=-1)

    @staticmethod
    def _need_context(context) -> DetectContext:
        if not isinstance(context, DetectContext) or context.sample is None or context.theta is None:
            raise ValueError("OracleDetector needs the context (sample and θ); use it through vr.Objective")
        return context

    # -- the protocol -----------------------------------------------------------------------------------------
    def detect(self, context: DetectContext) -> list[Detections]:
        """Black-box path: one candidate per row (or none: ``"out_of_view"`` when a corner is behind the camera,
        ``"no_detection"`` when ``fail_outside`` and a corner left the image)."""
        ctx = self._need_context(context)
        kp = np.asarray(ctx.move_points(self.true_corners(ctx.sample)))
        n = kp.shape[0]
        kp = kp + self._noise(ctx, n)
        out_of_image = self._outside(ctx, kp) if self.fail_outside else np.zeros(n, dtype=bool)
        behind = ~np.isfinite(kp).all(axis=(1, 2))
        dets = []
        for k in range(n):
            if behind[k]:
                dets.append(Detections.empty(FailureReason.OUT_OF_VIEW))
                continue
            if out_of_image[k]:
                dets.append(Detections.empty())
                continue
            box = np.concatenate([kp[k].min(axis=0), kp[k].max(axis=0)])
            dets.append(Detections(box[None], np.ones(1), kp[k][None]))
        return dets

    def detect_top(self, context: DetectContext) -> tuple[torch.Tensor, torch.Tensor]:
        """Differentiable path: ``conf (B,)`` (1, or 0 for a corner outside with ``fail_outside`` or behind the
        camera) and keypoints ``(B, 4, 2)`` differentiable w.r.t. a tensor θ in the context."""
        ctx = self._need_context(context)
        kp = ctx.move_points(self.true_corners(ctx.sample))
        kp = torch.as_tensor(kp) if not isinstance(kp, torch.Tensor) else kp
        n = kp.shape[0]
        kp = kp + torch.as_tensor(self._noise(ctx, n), dtype=kp.dtype, device=kp.device)
        conf = torch.ones(n, dtype=kp.dtype, device=kp.device)
        behind = ~torch.isfinite(kp.detach()).all(dim=2).all(dim=1)
        conf = torch.where(behind, torch.zeros_like(conf), conf)
        if self.fail_outside:
            outside = torch.as_tensor(self._outside(ctx, kp.detach().cpu().numpy()), device=kp.device)
            conf = torch.where(outside, torch.zeros_like(conf), conf)
        return conf, kp
