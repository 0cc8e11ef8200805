"""Camera attitude (roll, pitch, yaw) as the image homography ``K R K⁻¹``, and its 2D point transforms.

A rotation of the camera about its optical centre moves no 3D point and not the camera position, so the image it
takes is an exact function of the unrotated image: the homography ``H = K · R_cv · K⁻¹`` (pinhole ``K`` of the
image's pixels, ``R_cv`` the rotation in OpenCV camera axes). Hence ideal pose estimation is attitude-invariant
as long as the runway stays in the image.

Convention
----------
* Pixels, camera axes and LARD angles as in :mod:`vbl_robust.geometry.camera` (``R`` = camera → runway, columns
  forward, left, up; OpenCV pixels, pixel centres at integers).
* The perturbed camera is ``R' = R · Rz(−yaw) · Ry(−pitch) · Rx(roll)``: intrinsic rotations about the camera's
  **own** up, left and forward axes, in the Z-Y-X order of :func:`~vbl_robust.geometry.camera.lard_rotation`.
  For a level camera (zero pitch and roll) ``yaw_deg`` adds to the LARD heading and ``pitch_deg`` to the
  aeronautical pitch; ``roll_deg`` always adds to the LARD roll (it is the last rotation).
* **Signs** (aircraft convention, all positive = the usual positive attitude change):

  - ``pitch_deg > 0`` = nose **up**: the camera looks higher, the scene moves **down** in the image (``v`` grows);
  - ``yaw_deg > 0`` = nose **right** (heading increases): the scene moves **left** (``u`` decreases);
  - ``roll_deg > 0`` = right wing down: the scene turns counter-clockwise on screen (:mod:`.geometric`).

* Point map (source → perturbed pixels, homogeneous)::

      p' ~ H p,    H = M_roll · K · B (Rz(−yaw) Ry(−pitch))ᵀ Bᵀ · K⁻¹

  with ``B`` = :data:`~vbl_robust.geometry.camera.BODY_TO_CV` and ``M_roll`` the rotation about the principal
  point of :func:`~vbl_robust.perturb.geometric.roll_matrix` (equal to ``K B Rx(roll)ᵀ Bᵀ K⁻¹`` for square pixels,
  and used as such so that a roll-only homography is the roll of :mod:`.geometric`). Points that the rotation puts
  behind the camera (homogeneous ``w ≤ 0``) have no image: :func:`attitude_points` returns NaN for them.
* **Padding**: reflection without repeating the border pixel (``BORDER_REFLECT_101``), bilinear — as for roll.
  The images agree with ``cv2.warpPerspective`` (tested). Output pixels whose ray lies behind the unrotated camera
  (rotations beyond 90° minus the half-diagonal field of view: beyond ~50° for LARD's 60° FOV) have no source;
  each path fills them with finite values of its own.

:func:`attitude` (torch, kornia ``warp_perspective``, differentiable w.r.t. the angles) and
:func:`attitude_numpy` (``cv2.warpPerspective``, no gradient) are the image maps.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from kornia.geometry.transform import warp_perspective
from torch import nn

from vbl_robust.geometry.camera import BODY_TO_CV

from .family import Family, FrameContext, identity_like
from .geometric import roll, roll_matrix, roll_numpy, roll_points, roll_source_coords

__all__ = [
    "CAMERA_ATTITUDE",
    "Attitude",
    "attitude",
    "attitude_homography",
    "attitude_numpy",
    "attitude_points",
    "attitude_source_coords",
]

#: Homogeneous ``w`` below which a point counts as behind the camera (pixels have ``w`` ≈ 1 near the centre).
_W_MIN = 1e-9


def _axis_rotations(pitch_rad: torch.Tensor, yaw_rad: torch.Tensor) -> torch.Tensor:
    """``Rz(−yaw) · Ry(−pitch)`` (B, 3, 3) in body axes (forward, left, up), see :mod:`~vbl_robust.geometry.camera`."""
    cp, sp = torch.cos(-pitch_rad), torch.sin(-pitch_rad)
    cy, sy = torch.cos(-yaw_rad), torch.sin(-yaw_rad)
    zero, one = torch.zeros_like(cp), torch.ones_like(cp)
    ry = torch.stack([torch.stack([cp, zero, sp], -1), torch.stack([zero, one, zero], -1),
                      torch.stack([-sp, zero, cp], -1)], -2)
    rz = torch.stack([torch.stack([cy, -sy, zero], -1), torch.stack([sy, cy, zero], -1),
                      torch.stack([zero, zero, one], -1)], -2)
    return rz @ ry


def _pitch_yaw_homographies(pitch_deg: torch.Tensor, yaw_deg: torch.Tensor, K: torch.Tensor,
                            ) -> tuple[torch.Tensor, torch.Tensor]:
    """``(H_py, H_py⁻¹)`` (B, 3, 3): the pitch-and-yaw part of the homography and its exact inverse."""
    q = _axis_rotations(torch.deg2rad(pitch_deg), torch.deg2rad(yaw_deg))  # (B, 3, 3), perturbed → unperturbed
    b = torch.as_tensor(BODY_TO_CV, dtype=q.dtype, device=q.device)
    k = K.to(q.dtype)
    k_inv = torch.linalg.inv(k)
    q_cv = b @ q @ b.T  # the same rotation in OpenCV camera axes
    return k @ q_cv.transpose(-1, -2) @ k_inv, k @ q_cv @ k_inv


def _as_angles(roll_deg, pitch_deg, yaw_deg, *, dtype, device) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    angles = [torch.as_tensor(a, device=device).to(dtype).reshape(-1) for a in (roll_deg, pitch_deg, yaw_deg)]
    b = max(a.shape[0] for a in angles)
    out = []
    for name, a in zip(("roll_deg", "pitch_deg", "yaw_deg"), angles, strict=True):
        if a.shape[0] not in (1, b):
            raise ValueError(f"attitude: {name} has {a.shape[0]} values for a batch of {b}")
        out.append(a.expand(b))
    return out[0], out[1], out[2]


def _as_k(K, batch: int, dtype, device) -> torch.Tensor:
    k = torch.as_tensor(np.asarray(K, dtype=np.float64) if not isinstance(K, torch.Tensor) else K, device=device)
    k = k.to(dtype)
    if k.shape == (3, 3):
        k = k.expand(batch, 3, 3)
    if k.shape != (batch, 3, 3):
        raise ValueError(f"attitude: K must have shape (3, 3) or ({batch}, 3, 3), got {tuple(k.shape)}")
    return k


def attitude_homography(roll_deg, pitch_deg, yaw_deg, K, *, inverse: bool = False) -> torch.Tensor:
    """Homographies ``H`` (B, 3, 3) mapping source pixels to perturbed pixels (see module *Convention*).

    Args:
        roll_deg, pitch_deg, yaw_deg: ``(B,)`` or scalars (broadcast), degrees; tensors stay differentiable.
        K: ``(3, 3)`` or ``(B, 3, 3)`` pinhole matrix of the image's pixels.
        inverse: return ``H⁻¹`` (perturbed → source), composed exactly from the inverse rotations.

    Computed in float64 unless an angle is a float32 tensor.

    >>> H = attitude_homography(0.0, 5.0, 0.0, np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]]))
    >>> p = H[0] @ torch.tensor([320.0, 240.0, 1.0], dtype=H.dtype)
    >>> round(float(p[1] / p[2]), 3)                         # nose up 5°: the centre moves down by f·tan 5°
    283.744
    """
    ref = next((a for a in (roll_deg, pitch_deg, yaw_deg) if isinstance(a, torch.Tensor) and a.is_floating_point()),
               None)
    dtype = ref.dtype if ref is not None else torch.float64
    device = ref.device if ref is not None else None
    roll, pitch, yaw = _as_angles(roll_deg, pitch_deg, yaw_deg, dtype=dtype, device=device)
    k = _as_k(K, roll.shape[0], dtype, roll.device)
    h_py, h_py_inv = _pitch_yaw_homographies(pitch, yaw, k)
    center = k[:, :2, 2]
    m = roll_matrix(-roll if inverse else roll, center)  # (B, 2, 3); the inverse of a rotation by φ is by −φ
    bottom = torch.zeros_like(m[:, :1, :])
    bottom[..., 2] = 1.0
    m_roll = torch.cat([m, bottom], dim=-2)
    return h_py_inv @ m_roll if inverse else m_roll @ h_py


def _dehomogenise(x: torch.Tensor, y: torch.Tensor, w: torch.Tensor, behind):
    """``(x / w, y / w)``; where ``w ≤ 0`` the value ``behind`` (NaN for points) or ``w`` clamped (image samples).
    Never divides by zero, so gradients stay finite where the result is used."""
    ok = w > _W_MIN
    safe = torch.where(ok, w, torch.ones_like(w))
    u, v = x / safe, y / safe
    if behind is None:  # image sampling: a far but finite coordinate
        far = torch.where(ok, torch.zeros_like(w), 1.0 / _W_MIN * torch.ones_like(w))
        return torch.where(ok, u, x * far), torch.where(ok, v, y * far)
    nan = torch.full_like(u, behind)
    return torch.where(ok, u, nan), torch.where(ok, v, nan)


def attitude_points(points, roll_deg, pitch_deg, yaw_deg, K):
    """Move pixel points as :func:`attitude` moves the image content.

    Args:
        points: ``(B, N, 2)`` or ``(N, 2)`` (broadcast over the angles) pixels ``(u, v)``; numpy or torch.
        roll_deg, pitch_deg, yaw_deg: ``(B,)`` degrees (module *Convention*); K: ``(3, 3)`` pinhole matrix.

    Returns:
        ``(B, N, 2)`` of the input's array type (torch: differentiable w.r.t. the angles and points); NaN for a point
        that the rotation puts behind the camera.

    >>> K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    >>> attitude_points(np.array([[320.0, 240.0]]), 0.0, 0.0, np.array([5.0]), K).round(3).tolist()
    [[[276.256, 240.0]]]
    """
    is_torch = any(isinstance(a, torch.Tensor) for a in (points, roll_deg, pitch_deg, yaw_deg))
    ref = next((a for a in (points, roll_deg, pitch_deg, yaw_deg) if isinstance(a, torch.Tensor)
                and a.is_floating_point()), None)
    dtype = ref.dtype if ref is not None else torch.float64
    p = torch.as_tensor(points if isinstance(points, torch.Tensor) else np.asarray(points, np.float64)).to(dtype)
    if p.ndim == 2:
        p = p[None]
    if p.ndim != 3 or p.shape[-1] != 2:
        raise ValueError(f"attitude_points: points must have shape (B, N, 2) or (N, 2), got {tuple(p.shape)}")
    h = attitude_homography(*(torch.as_tensor(a).to(dtype) if not isinstance(a, torch.Tensor) else a.to(dtype)
                              for a in (roll_deg, pitch_deg, yaw_deg)), K)
    if p.shape[0] not in (1, h.shape[0]) and h.shape[0] != 1:
        raise ValueError(f"attitude_points: {p.shape[0]} point sets for {h.shape[0]} angle rows")
    x = h[:, None, 0, 0] * p[..., 0] + h[:, None, 0, 1] * p[..., 1] + h[:, None, 0, 2]
    y = h[:, None, 1, 0] * p[..., 0] + h[:, None, 1, 1] * p[..., 1] + h[:, None, 1, 2]
    w = h[:, None, 2, 0] * p[..., 0] + h[:, None, 2, 1] * p[..., 1] + h[:, None, 2, 2]
    u, v = _dehomogenise(x, y, w, float("nan"))
    out = torch.stack([u, v], dim=-1)
    return out if is_torch else out.numpy()


def attitude_source_coords(qu: torch.Tensor, qv: torch.Tensor, roll_deg, pitch_deg, yaw_deg, K,
                           ) -> tuple[torch.Tensor, torch.Tensor]:
    """Inverse map of :func:`attitude`: the source pixel shown at perturbed pixel ``(qu, qv)``.

    Args:
        qu, qv: ``(B, …)`` OpenCV coordinates in the perturbed image (computed in their dtype).
        roll_deg, pitch_deg, yaw_deg: ``(B,)`` degrees; K: ``(3, 3)`` pinhole matrix of the pixels.

    Returns:
        ``(su, sv)`` like ``qu``, not yet reflected into the image. The roll is undone first, exactly as
        :func:`~vbl_robust.perturb.geometric.roll_source_coords` does, then the pitch and yaw. A ray behind the
        unrotated camera gets a far, finite coordinate. Differentiable w.r.t. the angles.
    """
    dtype = qu.dtype
    k = torch.as_tensor(np.asarray(K, np.float64) if not isinstance(K, torch.Tensor) else K).to(qu.device, dtype)
    roll, pitch, yaw = _as_angles(roll_deg, pitch_deg, yaw_deg, dtype=dtype, device=qu.device)
    ru, rv = roll_source_coords(qu, qv, roll, k[:2, 2])
    _, h_inv = _pitch_yaw_homographies(pitch, yaw, k.expand(roll.shape[0], 3, 3))
    shape = (-1, *([1] * (qu.ndim - 1)))

    def e(i, j):
        return h_inv[:, i, j].reshape(shape)

    x = e(0, 0) * ru + e(0, 1) * rv + e(0, 2)
    y = e(1, 0) * ru + e(1, 1) * rv + e(1, 2)
    w = e(2, 0) * ru + e(2, 1) * rv + e(2, 2)
    return _dehomogenise(x, y, w, None)


def attitude(images: torch.Tensor, roll_deg, pitch_deg, yaw_deg, K) -> torch.Tensor:
    """Rotate the camera about its optical centre: warp images by ``H = K R K⁻¹`` with reflection padding.

    Args:
        images: ``(B, C, H, W)`` or ``(1, C, H, W)`` (broadcast over the angles) floating point.
        roll_deg, pitch_deg, yaw_deg: ``(B,)`` degrees (or scalars); signs in the module *Convention* (pitch up =
            scene down, yaw right = scene left, roll right wing down = scene counter-clockwise).
        K: ``(3, 3)`` pinhole matrix of the images' pixels (its principal point is the rotation centre).

    Returns:
        ``(B, C, H, W)``, same dtype as ``images``; differentiable w.r.t. the angles and ``images``.

    >>> K = np.array([[8.0, 0, 2], [0, 8.0, 2], [0, 0, 1]])
    >>> img = torch.zeros(1, 1, 5, 5); img[0, 0, 2, 2] = 1.0         # a dot at the principal point
    >>> out = attitude(img, 0.0, torch.tensor([7.125]), 0.0, K)       # nose up by atan(1/8): one pixel down
    >>> [int(i) for i in torch.nonzero(out[0, 0] > 0.5)[0]]
    [3, 2]
    """
    if images.ndim != 4:
        raise ValueError(f"attitude: images must have shape (B, C, H, W), got {tuple(images.shape)}")
    if not images.is_floating_point():
        raise ValueError(f"attitude: images must be floating point, got {images.dtype}")
    h = attitude_homography(*(torch.as_tensor(a).to(torch.float64) if not isinstance(a, torch.Tensor) else a
                              for a in (roll_deg, pitch_deg, yaw_deg)), K).to(images.device)
    b = h.shape[0]
    if images.shape[0] not in (1, b):
        raise ValueError(f"attitude: {images.shape[0]} images for {b} angle rows (give 1 image or one per row)")
    if images.shape[0] == 1 and b > 1:
        images = images.expand(b, -1, -1, -1)
    height, width = images.shape[-2:]
    return warp_perspective(images, h.to(images.dtype), (height, width), mode="bilinear", padding_mode="reflection",
                            align_corners=True)


def attitude_numpy(image: np.ndarray, roll_deg: float, pitch_deg: float, yaw_deg: float, K,
                   out: np.ndarray | None = None) -> np.ndarray:
    """OpenCV twin of :func:`attitude` for one image ``(H, W, C)``; no gradient.

    ``cv2.warpPerspective`` with the exact inverse homography (``WARP_INVERSE_MAP``), ``BORDER_REFLECT_101``,
    bilinear. ``out``: an optional contiguous array of the same shape and dtype to write into (not ``image``).
    """
    import cv2

    for name, a in (("roll_deg", roll_deg), ("pitch_deg", pitch_deg), ("yaw_deg", yaw_deg)):
        if not math.isfinite(float(a)):
            raise ValueError(f"attitude_numpy: {name} must be finite, got {a}")
    h_inv = attitude_homography(float(roll_deg), float(pitch_deg), float(yaw_deg), K, inverse=True)[0].numpy()
    height, width = image.shape[:2]
    res = cv2.warpPerspective(image, h_inv, (width, height), dst=out,
                              flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REFLECT_101)
    return res.reshape(image.shape)


class Attitude(nn.Module):
    """Module form of :func:`attitude`: ``Attitude(K)(images, roll_deg, pitch_deg, yaw_deg)``."""

    def __init__(self, K):
        super().__init__()
        self.K = np.asarray(K, dtype=np.float64)

    def forward(self, images: torch.Tensor, roll_deg, pitch_deg, yaw_deg) -> torch.Tensor:
        return attitude(images, roll_deg, pitch_deg, yaw_deg, self.K)


class _CameraAttitude(Family):
    """The registry's maps of ``roll_deg``, ``pitch_deg`` and ``yaw_deg``: one homography when pitch or yaw is in
    the box; a roll-only box keeps the rotation of :mod:`.geometric` bit for bit (it needs only the principal
    point)."""

    params = ("roll_deg", "pitch_deg", "yaw_deg")
    needs_K = ("pitch_deg", "yaw_deg")

    def _homography(self, v: dict) -> bool:
        return "pitch_deg" in v or "yaw_deg" in v

    def _angles(self, v: dict) -> list:
        like = next(iter(v.values()))
        return [v[n] if n in v else identity_like(like, 0.0) for n in self.params]

    def frame_numpy(self, frame, v, ctx: FrameContext, out):
        if self._homography(v):
            return attitude_numpy(frame, *(float(v.get(n, 0.0)) for n in self.params), ctx.K, out=out)
        return roll_numpy(frame, v["roll_deg"], ctx.center, out=out)

    def frame_torch(self, x, v, ctx: FrameContext):
        if self._homography(v):
            return attitude(x, *self._angles(v), ctx.K)
        return roll(x, v["roll_deg"], ctx.center)

    def points(self, points, v, ctx: FrameContext):
        if self._homography(v):
            return attitude_points(points, *self._angles(v), ctx.K)
        if ctx.center is None:
            raise ValueError("Perturbation.points: roll_deg needs the rotation centre (center=) or K")
        return roll_points(points, v["roll_deg"], ctx.center)

    def source_coords(self, qu, qv, v, ctx: FrameContext):
        if self._homography(v):
            if ctx.K is None:
                raise ValueError("Perturbation.source_coords: pitch_deg/yaw_deg need the intrinsics K")
            return attitude_source_coords(qu, qv, *self._angles(v), ctx.K)
        return roll_source_coords(qu, qv, v["roll_deg"], ctx.center)

    def source_matrix(self, v, ctx: FrameContext):
        if self._homography(v):
            if ctx.K is None:
                raise ValueError("Perturbation.source_matrix: pitch_deg/yaw_deg need the intrinsics K")
            angles = [torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in self._angles(v)]
            return attitude_homography(*angles, ctx.K, inverse=True).numpy()
        if ctx.center is None:
            raise ValueError("Perturbation.source_matrix: roll_deg needs the rotation centre (center=) or K")
        roll = torch.as_tensor(np.asarray(v["roll_deg"], dtype=np.float64))
        m = roll_matrix(-roll, torch.as_tensor(np.asarray(ctx.center, np.float64)).expand(roll.shape[0], 2))
        out = np.zeros((roll.shape[0], 3, 3))
        out[:, :2], out[:, 2, 2] = m.numpy(), 1.0  # the inverse of a roll by φ is the roll by −φ
        return out


#: the camera attitude family (registry entries ``roll_deg``, ``pitch_deg``, ``yaw_deg``)
CAMERA_ATTITUDE = _CameraAttitude()
