import cv2
import numpy as np
import pytest
import torch

from vbl_robust.geometry.camera import intrinsics, lard_rotation, project, runway_corners
from vbl_robust.perturb.geometric import Roll, roll, roll_numpy, roll_points

CENTER = (83.0, 57.5)  # principal point, deliberately not the image centre (79.5, 59.5)


def _to_tensor(img: np.ndarray, dtype=torch.float32) -> torch.Tensor:
    return torch.from_numpy(img.astype(np.float64) / 255.0).permute(2, 0, 1)[None].to(dtype)


def _to_hwc(t: torch.Tensor) -> np.ndarray:
    return t[0].permute(1, 2, 0).double().numpy()


def _outside_mask(h: int, w: int, angle: float, center) -> np.ndarray:
    """Output pixels whose source position falls outside the image (i.e. are produced by the padding)."""
    m = cv2.invertAffineTransform(cv2.getRotationMatrix2D(center, angle, 1.0))
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    su = m[0, 0] * u + m[0, 1] * v + m[0, 2]
    sv = m[1, 0] * u + m[1, 1] * v + m[1, 2]
    return (su < 0) | (su > w - 1) | (sv < 0) | (sv > h - 1)


@pytest.mark.parametrize("angle", [-30.0, -7.3, 12.9, 30.0])
def test_roll_equals_cv2_reflect101_interior_and_border(image, angle):
    f = image.astype(np.float32) / 255.0
    ref = cv2.warpAffine(
        f, cv2.getRotationMatrix2D(CENTER, angle, 1.0), (f.shape[1], f.shape[0]),
        flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101,
    )
    out = _to_hwc(roll(_to_tensor(image), torch.tensor([angle]), CENTER))
    border = _outside_mask(*f.shape[:2], angle, CENTER)
    assert border.sum() > 100 and (~border).sum() > 100
    # Tolerance 5e-5 (values in [0, 1], 1/80 of a uint8 step): float32 rounding of the sampling coordinates
    # only — kornia's "reflection" IS reflect-101. (OpenCV quantises coordinates to 1/32 px for float64 images,
    # so the comparison is made in float32.)
    assert np.abs(out - ref)[~border].max() < 5e-5
    assert np.abs(out - ref)[border].max() < 5e-5
    # ... and not BORDER_REFLECT (which repeats the edge pixel): the padded pixels differ visibly.
    ref_reflect = cv2.warpAffine(
        f, cv2.getRotationMatrix2D(CENTER, angle, 1.0), (f.shape[1], f.shape[0]),
        flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT,
    )
    assert np.abs(out - ref_reflect)[border].max() > 0.02


def test_roll_numpy_is_the_same_operation(image):
    f = image.astype(np.float32) / 255.0
    for angle in (-21.0, 4.5):
        a = roll_numpy(f, angle, CENTER)
        b = _to_hwc(roll(_to_tensor(image), torch.tensor([angle]), CENTER))
        assert np.abs(a - b).max() < 5e-5


def test_sign_is_camera_roll_right_wing_down():
    """Rolling the camera by +φ (LARD: R·Rx(φ)) moves the projected points exactly as roll_points(+φ)."""
    K = intrinsics(1024, 1024, 60.0)
    corners = runway_corners(3000.0, 45.0)
    C = np.array([-4000.0, 60.0, 300.0])
    R0 = lard_rotation(yaw_deg=3.0, pitch_lard_deg=87.0, roll_deg=2.0, runway_azimuth_deg=0.0)
    p0 = project(corners, R0, C, K)
    for phi in (-25.0, 10.0, 30.0):
        R1 = lard_rotation(yaw_deg=3.0, pitch_lard_deg=87.0, roll_deg=2.0 + phi, runway_azimuth_deg=0.0)
        moved = roll_points(p0, np.array([phi]), (K[0, 2], K[1, 2]))[0]
        np.testing.assert_allclose(moved, project(corners, R1, C, K), atol=1e-9)
    # right wing down: a point right of the centre moves up on screen (counter-clockwise)
    q = roll_points(np.array([[600.0, 512.0]]), np.array([10.0]), (512.0, 512.0))[0, 0]
    assert q[0] < 600.0 and q[1] < 512.0


@pytest.mark.parametrize("angle", [-30.0, 17.0, 90.0])
def test_bright_dot_moves_to_roll_points(angle):
    h, w = 90, 110
    p = np.array([75.3, 48.6])
    v, u = np.mgrid[0:h, 0:w]
    blob = np.exp(-((u - p[0]) ** 2 + (v - p[1]) ** 2) / (2 * 1.2**2))
    out = roll(torch.from_numpy(blob)[None, None], torch.tensor([angle], dtype=torch.float64), CENTER)[0, 0].numpy()
    expected = roll_points(p[None], np.array([angle]), CENTER)[0, 0]
    # centroid in a 7 px window: the reflection padding legitimately adds mirrored copies far away
    near = (u - expected[0]) ** 2 + (v - expected[1]) ** 2 < 7.0**2
    o = np.where(near, out, 0.0)
    centroid = np.array([(o * u).sum(), (o * v).sum()]) / o.sum()
    assert o.sum() > 0.95 * blob.sum()
    assert np.linalg.norm(centroid - expected) < 0.01  # px; bilinear resampling blurs but does not shift


def test_batch_broadcast_and_module(image):
    x = _to_tensor(image)
    angles = torch.tensor([-5.0, 0.0, 13.0])
    batched = roll(x, angles, CENTER)
    assert batched.shape == (3, 3, *image.shape[:2])
    for k in range(3):
        torch.testing.assert_close(batched[k : k + 1], roll(x, angles[k : k + 1], CENTER))
    torch.testing.assert_close(batched[1:2], x, atol=2e-5, rtol=0)  # 0° is the identity (float32 grid rounding)
    per_image = roll(x.expand(3, -1, -1, -1), angles, torch.tensor(CENTER).expand(3, 2))
    torch.testing.assert_close(per_image, batched)
    torch.testing.assert_close(Roll(CENTER)(x, angles), batched)


def test_default_center_is_lard_principal_point():
    x = torch.rand(1, 1, 16, 20, dtype=torch.float64)
    torch.testing.assert_close(roll(x, torch.tensor([9.0]), None), roll(x, torch.tensor([9.0]), (10.0, 8.0)))


def test_gradcheck_angle_float64(make_image):
    img = torch.from_numpy(make_image(24, 30, seed=1).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    angles = torch.tensor([7.31, -12.47], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: roll(img, a, (14.2, 11.7)), (angles,), eps=1e-6, atol=1e-5, fast_mode=True)


def test_gradcheck_roll_points_float64():
    pts = torch.tensor([[[3.0, 4.0], [10.0, -2.0]]] * 2, dtype=torch.float64, requires_grad=True)
    angles = torch.tensor([5.0, -40.0], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda p, a: roll_points(p, a, (1.5, 2.5)), (pts, angles))


def test_roll_points_numpy_and_torch_agree():
    pts = np.random.default_rng(0).random((3, 4, 2)) * 100
    angles = np.array([-30.0, 0.0, 12.5])
    a = roll_points(pts, angles, (50.0, 40.0))
    b = roll_points(torch.from_numpy(pts), torch.from_numpy(angles), (50.0, 40.0)).numpy()
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(roll_points(pts, np.zeros(3), (50.0, 40.0)), pts, atol=1e-12)
    back = roll_points(a, -angles, (50.0, 40.0))
    np.testing.assert_allclose(back, pts, atol=1e-9)


def test_errors():
    with pytest.raises(ValueError, match="images must have shape"):
        roll(torch.rand(3, 8, 8), torch.tensor([1.0]))
    with pytest.raises(ValueError, match="2 images for 3 angles"):
        roll(torch.rand(2, 3, 8, 8), torch.tensor([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="floating point"):
        roll(torch.zeros(1, 3, 8, 8, dtype=torch.uint8), torch.tensor([1.0]))
    with pytest.raises(ValueError, match="center"):
        roll(torch.rand(1, 3, 8, 8), torch.tensor([1.0, 2.0]), center=torch.zeros(3, 2))
    with pytest.raises(ValueError, match="points must have shape"):
        roll_points(np.zeros((4, 3)), np.array([1.0]), (0.0, 0.0))
    with pytest.raises(ValueError, match="finite"):
        roll_numpy(np.zeros((4, 4, 3), np.float32), float("nan"))
