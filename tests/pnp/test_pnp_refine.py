"""Batched LM refinement: Rodrigues formula, convergence, never worse than OpenCV's LM."""

from __future__ import annotations

import cv2
import numpy as np

from vbl_robust.pnp.refine import refine_lm, residuals, rotvec_to_matrix


def test_rotvec_to_matrix_matches_opencv_including_tiny_angles() -> None:
    rng = np.random.default_rng(0)
    w = np.concatenate([rng.normal(size=(50, 3)), rng.normal(size=(20, 3)) * 1e-6, np.zeros((1, 3))])
    ours = rotvec_to_matrix(w)
    for wi, Ri in zip(w, ours, strict=True):
        np.testing.assert_allclose(Ri, cv2.Rodrigues(wi)[0], atol=1e-14)


def test_refinement_reaches_a_lower_stationary_point_than_opencv_lm(view) -> None:
    rng = np.random.default_rng(1)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
    for d in (300.0, 2000.0, 4500.0, 6000.0):
        v = view(d, yaw_offset_deg=rng.uniform(-10, 10), roll_deg=rng.uniform(-20, 20))
        x = v.points_2d + rng.normal(0.0, 0.5, size=(4, 2))
        _, rvecs, tvecs, errs = cv2.solvePnPGeneric(v.corners_3d, x, v.K, None, flags=cv2.SOLVEPNP_IPPE)
        i = int(np.argmin(np.ravel(errs)))
        r_cv, t_cv = cv2.solvePnPRefineLM(v.corners_3d, x, v.K, None, rvecs[i].copy(), tvecs[i].copy(), crit)
        R0 = rotvec_to_matrix(rvecs[i].reshape(1, 3))
        R, t, cost = refine_lm(v.corners_3d, x[None], v.K, R0, tvecs[i].reshape(1, 3))
        _, _, r = residuals(v.corners_3d, x[None], v.K, rotvec_to_matrix(r_cv.reshape(1, 3)), t_cv.reshape(1, 3))
        assert cost[0] <= np.sum(r * r) * (1 + 1e-12)
        # stationary: no further LM progress
        R2, t2, cost2 = refine_lm(v.corners_3d, x[None], v.K, R, t)
        np.testing.assert_allclose(t2, t, rtol=0, atol=1e-9 * np.linalg.norm(t))
        assert cost2[0] <= cost[0] * (1 + 1e-12)


def test_refinement_keeps_non_finite_starts_unchanged(view) -> None:
    v = view(1000.0)
    R0 = np.stack([np.eye(3), np.full((3, 3), np.nan)])
    t0 = np.array([[0.0, 0.0, 1000.0], [np.nan, 0.0, 0.0]])
    R, t, cost = refine_lm(v.corners_3d, np.stack([v.points_2d] * 2), v.K, R0, t0)
    assert np.isfinite(cost[0]) and np.isnan(cost[1])
    assert np.all(np.isnan(t[1, :1]))
