"""Both IPPE poses of a planar target for a whole batch of rows at once, in closed form.

Hand-written in NumPy because OpenCV has no batched IPPE: ``cv2.solvePnPGeneric(..., SOLVEPNP_IPPE)`` solves one
row per call (tens of µs each, plus Python overhead), which dominated ``solve(method="ippe_lm")``. The algorithm
is Collins & Bartoli, *Infinitesimal Plane-Based Pose Estimation*, IJCV 109 (2014), written from the paper:

1. **Canonical object frame**: centre the corners and rotate their best-fit plane onto ``z = 0`` (SVD, a proper
   rotation ``Rc``), giving plane coordinates ``u_i`` (4, 2) with centroid 0.
2. **Homography** ``H`` from ``u_i`` to the normalised image points ``m_i = K⁻¹ x_i`` (exact for 4 points: the
   projective basis of each side, both sides isotropically normalised for conditioning).
3. **Jacobian at the centroid**: ``v = H(0)`` (where the centroid projects) and ``J = ∂H(u)/∂u`` at 0 (2 × 2).
4. **Rotations**: with ``Rv`` any rotation taking ``e₃`` to the line of sight ``ṽ = (v, 1)/‖(v, 1)‖``, the first two
   columns of the camera rotation are ``Rv Q`` where the top 2 × 2 block of ``Q`` is ``A/γ``,
   ``A = B⁻¹ J``, ``B`` = the top-left block of ``[I₂ | −v] Rv`` and ``γ`` the largest singular value of ``A``;
   the third row of ``Q`` is ``±(b₀, b₁)`` (unit columns, orthogonal), which gives the two solutions of the
   planar ambiguity. The third column is the cross product.
5. **Translations**: for each rotation, the linear least-squares ``t`` of ``m_i × (R u_i + t) = 0``.

The poses are world → camera in OpenCV axes (``X_cv = R z + t``), like ``cv2.solvePnPGeneric``. Unlike OpenCV,
``1 − ‖column‖²`` is clamped at 0 before its square root: OpenCV returns NaN poses for some exact (noise-free)
keypoint sets where it rounds below 0, this code returns the (single, doubled) pose there. Rows whose centroid
projects to infinity give non-finite poses.
"""

from __future__ import annotations

import numpy as np


def plane_frame(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical frame of (nearly) coplanar points z (4, 3).

    Returns:
        ``(Rc (3, 3), c (3,), u (4, 2))``: a proper rotation whose rows are the plane's two in-plane axes and its
        normal, the centroid, and the plane coordinates ``u = ((z − c) Rcᵀ)[:, :2]``.
    """
    c = z.mean(axis=0)
    _, _, vt = np.linalg.svd(z - c)
    Rc = vt.copy()
    Rc[2] = np.cross(Rc[0], Rc[1])  # right-handed: the normal's sign does not change the two IPPE poses
    return Rc, c, ((z - c) @ Rc.T)[:, :2]


def _basis_inverse(u: np.ndarray) -> np.ndarray:
    """Inverse (3, 3) of the projective basis matrix of 4 points u (4, 2) (columns λᵢ (uᵢ, 1), i < 3)."""
    P = np.vstack([u[:3].T, np.ones(3)])
    lam = np.linalg.solve(P, np.append(u[3], 1.0))
    return np.linalg.inv(P * lam)


def _tri(ax, ay, bx, by, cx, cy):  # noqa: ANN001, ANN202 - arrays of one shape
    """Twice the signed area of the triangles (a, b, c)."""
    return (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)


def _image_side(x: np.ndarray, K: np.ndarray, Ainv: np.ndarray, su: float) -> tuple:
    """The image side of :func:`ippe_poses`: normalised image coordinates ``mx, my`` (4, B), the Jacobian
    ``(j00, j01, j10, j11)`` of the plane → image homography at the plane points' centroid (unnormalised units)
    and the centroid's image ``p, q``."""
    # normalised image coordinates m = K⁻¹ (x, 1), points first: (4, B)
    Ki = np.linalg.inv(K)
    xu, xv = x[:, :, 0].T, x[:, :, 1].T
    h0 = Ki[0, 0] * xu + Ki[0, 1] * xv + Ki[0, 2]
    h1 = Ki[1, 0] * xu + Ki[1, 1] * xv + Ki[1, 2]
    h2 = Ki[2, 0] * xu + Ki[2, 1] * xv + Ki[2, 2]
    mx, my = h0 / h2, h1 / h2
    cx = (mx[0] + mx[1] + mx[2] + mx[3]) * 0.25
    cy = (my[0] + my[1] + my[2] + my[3]) * 0.25
    dx, dy = mx - cx, my - cy
    sm = np.sqrt((dx[0] ** 2 + dy[0] ** 2 + dx[1] ** 2 + dy[1] ** 2 + dx[2] ** 2 + dy[2] ** 2
                  + dx[3] ** 2 + dy[3] ** 2) * 0.25)
    px, py = dx / sm, dy / sm  # isotropically normalised image points

    # image side: q₄ = Σ μᵢ qᵢ (Cramer), then H' = [μᵢ qᵢ] Ainv maps u/su to (m − c)/sm
    det = _tri(px[0], py[0], px[1], py[1], px[2], py[2])
    mu = (_tri(px[3], py[3], px[1], py[1], px[2], py[2]) / det,
          _tri(px[0], py[0], px[3], py[3], px[2], py[2]) / det,
          _tri(px[0], py[0], px[1], py[1], px[3], py[3]) / det)
    qx = [mu[i] * px[i] for i in range(3)]
    qy = [mu[i] * py[i] for i in range(3)]
    qw = mu

    def hrow(q: list) -> list:
        return [q[0] * Ainv[0, j] + q[1] * Ainv[1, j] + q[2] * Ainv[2, j] for j in range(3)]

    H0, H1, H2 = hrow(qx), hrow(qy), hrow(qw)
    # the centroid u = 0 maps to v; J = ∂(image)/∂u there, back in unnormalised units
    vx_n, vy_n = H0[2] / H2[2], H1[2] / H2[2]
    scale = sm / (su * H2[2])
    j00, j01 = (H0[0] - vx_n * H2[0]) * scale, (H0[1] - vx_n * H2[1]) * scale
    j10, j11 = (H1[0] - vy_n * H2[0]) * scale, (H1[1] - vy_n * H2[1]) * scale
    p, q = cx + sm * vx_n, cy + sm * vy_n
    return mx, my, (j00, j01, j10, j11), p, q


def ippe_poses(z: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two IPPE poses of each row.

    Args:
        z: (4, 3) coplanar object points (runway corners), metres; no three collinear.
        x: (B, 4, 2) float64 pixels (OpenCV convention) of the points, no three collinear per row.
        K: (3, 3) pinhole intrinsics.

    Returns:
        ``(R, t)``: (B, 2, 3, 3) world → camera rotations and (B, 2, 3) translations (OpenCV axes), the two
        solutions of the planar ambiguity in no particular order. Non-finite where a row has no IPPE pose.

    Example:
        >>> from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners, world_to_cv
        >>> Z, K = runway_corners(3000.0, 45.0), intrinsics()
        >>> Rw, C = lard_rotation(4.0, 86.0, 3.0, 0.0), np.array([-1500.0, 20.0, 95.0])
        >>> R, t = ippe_poses(Z, project(Z, Rw, C, K)[None], K)
        >>> R_true, t_true = world_to_cv(Rw, C)
        >>> bool(min(np.abs(R[0, i] - R_true).max() for i in range(2)) < 1e-9)
        True
    """
    Rc, c, u = plane_frame(z)
    su = np.sqrt(np.mean(np.sum(u * u, axis=1)))
    Ainv = _basis_inverse(u / su)  # plane side of the homography, the same for every row

    mx, my, (j00, j01, j10, j11), p, q = _image_side(x, K, Ainv, su)

    # Rv: the rotation about e₃ × a taking e₃ to the line of sight a = (p, q, 1)/‖·‖
    n = np.sqrt(p * p + q * q + 1.0)
    a0, a1, a2 = p / n, q / n, 1.0 / n
    k = 1.0 / (1.0 + a2)
    rv = np.array([[1.0 - a0 * a0 * k, -a0 * a1 * k, a0],
                   [-a0 * a1 * k, 1.0 - a1 * a1 * k, a1],
                   [-a0, -a1, a2]])  # (3, 3, B)
    b00, b01 = rv[0, 0] - p * rv[2, 0], rv[0, 1] - p * rv[2, 1]
    b10, b11 = rv[1, 0] - q * rv[2, 0], rv[1, 1] - q * rv[2, 1]
    dinv = 1.0 / (b00 * b11 - b01 * b10)
    a00 = dinv * (b11 * j00 - b01 * j10)
    a01 = dinv * (b11 * j01 - b01 * j11)
    a10 = dinv * (b00 * j10 - b10 * j00)
    a11 = dinv * (b00 * j11 - b10 * j01)
    s00, s01, s11 = a00 * a00 + a10 * a10, a00 * a01 + a10 * a11, a01 * a01 + a11 * a11  # AᵀA
    gamma = np.sqrt(0.5 * (s00 + s11 + np.sqrt((s00 - s11) ** 2 + 4.0 * s01 * s01)))
    r00, r01, r10, r11 = a00 / gamma, a01 / gamma, a10 / gamma, a11 / gamma
    b0 = np.sqrt(np.maximum(1.0 - r00 * r00 - r10 * r10, 0.0))
    b1 = np.sqrt(np.maximum(1.0 - r01 * r01 - r11 * r11, 0.0))
    b1 = np.where(r00 * r01 + r10 * r11 > 0.0, -b1, b1)  # b₀ b₁ = −(column 0 · column 1)

    # the two planar solutions: third row ±(b₀, b₁); Gram–Schmidt keeps R orthonormal where b was clamped
    B = x.shape[0]
    R = np.empty((B, 2, 3, 3))
    t = np.empty((B, 2, 3))
    for s, sign in enumerate((1.0, -1.0)):
        c0 = np.array([r00, r10, sign * b0])
        c1 = np.array([r01, r11, sign * b1])
        c0 = c0 / np.sqrt(c0[0] ** 2 + c0[1] ** 2 + c0[2] ** 2)
        c1 = c1 - (c0[0] * c1[0] + c0[1] * c1[1] + c0[2] * c1[2]) * c0
        c1 = c1 / np.sqrt(c1[0] ** 2 + c1[1] ** 2 + c1[2] ** 2)
        c2 = np.array([c0[1] * c1[2] - c0[2] * c1[1], c0[2] * c1[0] - c0[0] * c1[2], c0[0] * c1[1] - c0[1] * c1[0]])
        Q = np.stack([c0, c1, c2], axis=1)  # (3, 3, B), columns in the line-of-sight frame
        Rcan = rv[:, 0, None] * Q[0] + rv[:, 1, None] * Q[1] + rv[:, 2, None] * Q[2]  # Rv Q: plane → camera
        tc = _translation(Rcan, u, mx, my)
        # world → camera, with canonical = Rc (z − c); explicit sums keep every row independent of the batch
        Rw = Rcan[:, 0, None] * Rc[0, :, None] + Rcan[:, 1, None] * Rc[1, :, None] + Rcan[:, 2, None] * Rc[2, :, None]
        R[:, s] = np.moveaxis(Rw, -1, 0)
        t[:, s] = (tc - (Rw[:, 0] * c[0] + Rw[:, 1] * c[1] + Rw[:, 2] * c[2])).T
    return R, t


def _translation(Rcan: np.ndarray, u: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    """Least-squares t (3, B) of mₓ (r₂·u + t₂) = r₀·u + t₀ (and likewise for m_y) over the 4 points."""
    rx = Rcan[0, 0] * u[:, 0, None] + Rcan[0, 1] * u[:, 1, None]  # (4, B)
    ry = Rcan[1, 0] * u[:, 0, None] + Rcan[1, 1] * u[:, 1, None]
    rz = Rcan[2, 0] * u[:, 0, None] + Rcan[2, 1] * u[:, 1, None]
    bx, by = mx * rz - rx, my * rz - ry  # t₀ − mₓ t₂ = bₓ, t₁ − m_y t₂ = b_y
    mxb, myb = mx.mean(axis=0), my.mean(axis=0)
    cx, cy = mx - mxb, my - myb  # centred: the normal equations in t₂ alone, without cancellation
    t2 = -(cx * bx + cy * by).sum(axis=0) / (cx * cx + cy * cy).sum(axis=0)
    return np.stack([bx.mean(axis=0) + mxb * t2, by.mean(axis=0) + myb * t2, t2])
