"""Camera attitude as the homography K R K⁻¹ (perturb/rotation.py): OpenCV agreement, signs, exact point maps."""

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from vbl_robust.geometry.camera import (
    BODY_TO_CV,
    intrinsics,
    lard_rotation,
    project,
    rot_x,
    rot_y,
    rot_z,
    runway_corners,
)
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.geometric import roll_numpy, roll_points
from vbl_robust.perturb.rotation import (
    Attitude,
    attitude,
    attitude_homography,
    attitude_numpy,
    attitude_points,
    attitude_source_coords,
)
from vbl_robust.space import ParameterBox

# principal point deliberately off the image centre (79.5, 59.5); f for a 70° horizontal FOV
K = intrinsics(160, 120, 70.0)
K[:2, 2] = (83.0, 57.5)
ANGLES = [(0.0, 6.0, 0.0), (0.0, 0.0, -9.0), (3.0, 4.0, -6.0), (-12.0, -7.5, 11.0)]


def _to_tensor(img: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(img.astype(np.float32) / 255.0).permute(2, 0, 1)[None]


def _reference_h(roll, pitch, yaw, k=K) -> np.ndarray:
    """H = K · B Qᵀ Bᵀ · K⁻¹ with Q = Rz(−yaw) Ry(−pitch) Rx(roll), built from geometry.camera alone."""
    q = rot_z(-yaw) @ rot_y(-pitch) @ rot_x(roll)
    return k @ BODY_TO_CV @ q.T @ BODY_TO_CV.T @ np.linalg.inv(k)


def _outside(h_mat: np.ndarray, h: int, w: int) -> np.ndarray:
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    src = np.linalg.inv(h_mat) @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    su, sv = (src[:2] / src[2]).reshape(2, h, w)
    return (su < 0) | (su > w - 1) | (sv < 0) | (sv > h - 1)


@pytest.mark.parametrize("angles", ANGLES)
def test_equals_cv2_warp_perspective_reflect101(image, angles):
    """kornia's warp with our H against cv2.warpPerspective with the independently built H (OpenCV inverts it)."""
    f = image.astype(np.float32) / 255.0
    h_ref = _reference_h(*angles)
    np.testing.assert_allclose(attitude_homography(*angles, K)[0].numpy(), h_ref, atol=1e-12)
    ref = cv2.warpPerspective(f, h_ref, (f.shape[1], f.shape[0]), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT_101)
    out = attitude(_to_tensor(image), *(torch.tensor([a]) for a in angles), K)[0].permute(1, 2, 0).numpy()
    border = _outside(h_ref, *f.shape[:2])
    assert border.sum() > 50 and (~border).sum() > 1000
    # 1e-4 of full scale (1/40 of a uint8 step): float32 sampling coordinates and OpenCV's 1/32 px fixed point
    assert np.abs(out - ref)[~border].max() < 1e-4
    assert np.abs(out - ref)[border].max() < 1e-4
    # ... and the padding is reflect-101, not BORDER_REFLECT (which repeats the edge pixel)
    other = cv2.warpPerspective(f, h_ref, (f.shape[1], f.shape[0]), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REFLECT)
    assert np.abs(out - other)[border].max() > 3e-3  # > 30x the tolerance (smooth rows give small gaps)
    # the OpenCV twin is the same operation
    assert np.abs(attitude_numpy(f, *angles, K) - out).max() < 1e-4


def test_signs_are_the_aircraft_convention():
    """Nose up: the scene moves down; nose right: the scene moves left; right wing down: counter-clockwise."""
    c = np.array([[K[0, 2], K[1, 2]]])
    up = attitude_points(c, 0.0, np.array([5.0]), 0.0, K)[0, 0]
    right = attitude_points(c, 0.0, 0.0, np.array([5.0]), K)[0, 0]
    assert up[1] == pytest.approx(K[1, 2] + K[1, 1] * np.tan(np.radians(5.0))) and up[0] == pytest.approx(K[0, 2])
    assert right[0] == pytest.approx(K[0, 2] - K[0, 0] * np.tan(np.radians(5.0))) and right[1] == pytest.approx(K[1, 2])
    q = attitude_points(c + [[40.0, 0.0]], np.array([10.0]), 0.0, 0.0, K)[0, 0]
    assert q[1] < K[1, 2]  # a point right of the centre moves up


@pytest.mark.parametrize("angles", [(0.0, 5.0, 0.0), (0.0, 0.0, 8.0), (7.0, -4.0, 12.0), (-25.0, 9.0, -15.0)])
def test_points_are_the_rotated_cameras_projection(angles):
    """The moved corners are exactly what the camera R' = R · Rz(−yaw) Ry(−pitch) Rx(roll) sees."""
    roll, pitch, yaw = angles
    k = intrinsics(1024, 1024, 60.0)
    corners = runway_corners(3000.0, 45.0)
    c = np.array([-4000.0, 60.0, 300.0])
    r0 = lard_rotation(yaw_deg=3.0, pitch_lard_deg=87.0, roll_deg=2.0, runway_azimuth_deg=0.0)
    r1 = r0 @ rot_z(-yaw) @ rot_y(-pitch) @ rot_x(roll)
    moved = attitude_points(project(corners, r0, c, k), np.array([roll]), np.array([pitch]), np.array([yaw]), k)[0]
    np.testing.assert_allclose(moved, project(corners, r1, c, k), atol=1e-9)


def test_level_camera_pitch_and_yaw_are_lard_pitch_and_heading():
    k = intrinsics(1024, 1024, 60.0)
    corners, c = runway_corners(3000.0, 45.0), np.array([-4000.0, 60.0, 300.0])
    level = lard_rotation(yaw_deg=0.0, pitch_lard_deg=90.0, roll_deg=0.0, runway_azimuth_deg=0.0)
    p0 = project(corners, level, c, k)
    tilted = lard_rotation(yaw_deg=4.0, pitch_lard_deg=90.0 + 3.0, roll_deg=0.0, runway_azimuth_deg=0.0)
    # heading first, then pitch about the new left axis: yaw 4°, pitch 3°
    np.testing.assert_allclose(attitude_points(p0, 0.0, np.array([3.0]), np.array([4.0]), k)[0],
                               project(corners, tilted, c, k), atol=1e-9)


def test_roll_only_is_the_roll_of_geometric(image):
    f = image.astype(np.float32) / 255.0
    center = (K[0, 2], K[1, 2])
    np.testing.assert_allclose(attitude_numpy(f, 13.0, 0.0, 0.0, K), roll_numpy(f, 13.0, center), atol=1e-6)
    pts = np.random.default_rng(0).random((5, 2)) * 100
    np.testing.assert_allclose(attitude_points(pts, np.array([13.0]), 0.0, 0.0, K),
                               roll_points(pts, np.array([13.0]), center), atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(angles=st.tuples(*(st.floats(-30, 30),) * 3),
       pts=st.lists(st.tuples(st.floats(0, 159), st.floats(0, 119)), min_size=1, max_size=5))
def test_source_coords_invert_the_point_map(angles, pts):
    p = torch.tensor(pts, dtype=torch.float64)
    a = [torch.tensor([v], dtype=torch.float64) for v in angles]
    moved = attitude_points(p, *a, K)[0]
    su, sv = attitude_source_coords(moved[None, :, 0], moved[None, :, 1], *a, torch.tensor(K))
    np.testing.assert_allclose(torch.stack([su[0], sv[0]], -1).numpy(), pts, atol=1e-8)


@settings(max_examples=30, deadline=None)
@given(a=st.floats(-20, 20), b=st.floats(-20, 20), axis=st.sampled_from([0, 1, 2]))
def test_rotations_about_one_axis_add_up(a, b, axis):
    """Pitch by a then by b (from the pitched image) is pitch by a + b; the same for yaw and roll."""
    def move(pts, angle):
        angles = [0.0, 0.0, 0.0]
        angles[axis] = np.array([angle])
        return attitude_points(pts, *angles, K)[0]

    pts = np.array([[20.0, 30.0], [140.0, 100.0], [83.0, 57.5]])
    np.testing.assert_allclose(move(move(pts, a), b), move(pts, a + b), atol=1e-7)


def test_a_bright_dot_moves_to_the_mapped_point():
    h, w = 120, 160
    p = np.array([101.3, 38.6])
    v, u = np.mgrid[0:h, 0:w]
    blob = np.exp(-((u - p[0]) ** 2 + (v - p[1]) ** 2) / (2 * 1.2**2))
    angles = (8.0, -5.0, 7.0)
    out = attitude(torch.from_numpy(blob)[None, None], *(torch.tensor([a], dtype=torch.float64) for a in angles),
                   K)[0, 0].numpy()
    expected = attitude_points(p[None], *(np.array([a]) for a in angles), K)[0, 0]
    near = (u - expected[0]) ** 2 + (v - expected[1]) ** 2 < 7.0**2
    o = np.where(near, out, 0.0)
    centroid = np.array([(o * u).sum(), (o * v).sum()]) / o.sum()
    assert np.linalg.norm(centroid - expected) < 0.05  # px (the homography's local scale changes the blob a little)


def test_points_behind_the_camera_are_nan_and_images_stay_finite(image):
    pts = np.array([[K[0, 2], K[1, 2]], [0.0, 0.0]])
    moved = attitude_points(pts, 0.0, np.array([120.0]), 0.0, K)
    assert np.isnan(moved[0, 0]).all()
    out = attitude(_to_tensor(image), 0.0, torch.tensor([95.0]), 0.0, K)
    assert torch.isfinite(out).all()
    assert np.isfinite(attitude_numpy(image.astype(np.float32) / 255.0, 0.0, 95.0, 0.0, K)).all()
    t = torch.tensor([120.0], dtype=torch.float64, requires_grad=True)
    kp = attitude_points(torch.tensor(pts), 0.0, t, 0.0, K)
    torch.where(torch.isfinite(kp), kp, 0.0).sum().backward()
    assert torch.isfinite(t.grad).all()  # no NaN leaks into the gradient


def test_gradcheck_angles_float64(make_image):
    img = torch.from_numpy(make_image(18, 22, seed=2).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    k = np.array([[20.0, 0.0, 11.3], [0.0, 20.0, 8.6], [0.0, 0.0, 1.0]])
    angles = [torch.tensor(v, dtype=torch.float64, requires_grad=True) for v in ([4.1, -7.3], [3.3, 6.2], [-5.1, 2.9])]
    assert torch.autograd.gradcheck(lambda r, p, y: attitude(img, r, p, y, k), angles, eps=1e-6, atol=1e-5,
                                    fast_mode=True)
    pts = torch.tensor([[3.0, 4.0], [12.0, 7.0]], dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda r, p, y: attitude_points(pts, r, p, y, k), angles)


def test_batch_broadcast_module_and_errors(image):
    x = _to_tensor(image)
    pitch = torch.tensor([-3.0, 0.0, 5.0])
    batched = attitude(x, 0.0, pitch, 0.0, K)
    for i in range(3):
        torch.testing.assert_close(batched[i : i + 1], attitude(x, 0.0, pitch[i : i + 1], 0.0, K))
    torch.testing.assert_close(batched[1:2], x, atol=2e-5, rtol=0)
    torch.testing.assert_close(Attitude(K)(x, 0.0, pitch, 0.0), batched)
    with pytest.raises(ValueError, match="images must have shape"):
        attitude(x[0], 0.0, pitch, 0.0, K)
    with pytest.raises(ValueError, match="K must have shape"):
        attitude(x, 0.0, pitch, 0.0, np.eye(2))
    with pytest.raises(ValueError, match="pitch_deg has 2 values"):
        attitude(x, torch.zeros(3), torch.zeros(2), 0.0, K)
    with pytest.raises(ValueError, match="finite"):
        attitude_numpy(image, 0.0, float("nan"), 0.0, K)


def test_the_composer_needs_k_for_pitch_and_yaw(image):
    p = Perturbation(ParameterBox({"roll_deg": (-5, 5), "yaw_deg": (-5, 5)}))
    with pytest.raises(ValueError, match="yaw_deg need the camera intrinsics"):
        p.images(image, np.array([[1.0, 2.0]]))
    with pytest.raises(ValueError, match="not the principal point"):
        p.images(image, np.array([[1.0, 2.0]]), K=K, center=(10.0, 10.0))
    out = p.images(image, np.array([[1.0, 2.0]]), K=K, center=(K[0, 2], K[1, 2]))
    assert out.shape == (1, *image.shape)
