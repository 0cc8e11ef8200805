import numpy as np
import pytest
import torch

from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.geometric import roll, roll_points
from vbl_robust.perturb.photometric import contrast
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})
CENTER = (77.0, 61.5)


def test_unknown_name_lists_known_ones():
    known = ", ".join(PERTURBATIONS)
    with pytest.raises(ValueError, match=rf"unknown parameter 'fog'; known perturbations: {known}$"):
        Perturbation(ParameterBox({"roll_deg": (-5, 5), "fog": (0.5, 2)}))
    with pytest.raises(ValueError, match="contrast.*>= 0"):
        Perturbation(ParameterBox({"contrast": (-0.5, 2)}))
    with pytest.raises(ValueError, match="haze.*<= 1"):
        Perturbation(ParameterBox({"haze": (0.0, 1.5)}))
    assert list(PERTURBATIONS) == ["roll_deg", "pitch_deg", "yaw_deg", "blur_px", "motion_blur_px", "haze",
                                   "contrast", "brightness", "gamma", "noise_std"]


def test_theta_validation():
    p = Perturbation(BOX)
    with pytest.raises(ValueError, match=r"theta must have shape \(N, 2\)"):
        p.images(np.zeros((4, 4, 3), np.uint8), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        p.images(np.zeros((4, 4, 3), np.uint8), np.array([[np.nan, 1.0]]))
    assert p.check_theta(np.array([1.0, 2.0])).shape == (1, 2)


def test_numpy_and_torch_modes_agree(image):
    p = Perturbation(BOX)
    theta = np.array([[0.0, 1.0], [-23.5, 0.4], [11.2, 2.5], [30.0, 1.3]])
    a = p.images(image, theta, center=CENTER)
    assert a.shape == (4, *image.shape) and a.dtype == np.float32
    b = p.images(torch.from_numpy(image).permute(2, 0, 1), torch.from_numpy(theta), center=CENTER)
    assert b.shape == (4, 3, *image.shape[:2]) and b.dtype == torch.float32
    np.testing.assert_allclose(a, b.permute(0, 2, 3, 1).numpy(), atol=1e-4)
    np.testing.assert_allclose(a[0], image / 255.0, atol=1e-6)  # identity θ
    # the same as composing the functions: roll first, then contrast
    x = torch.from_numpy(image).permute(2, 0, 1)[None].float() / 255.0
    manual = contrast(roll(x, torch.tensor([-23.5]), CENTER), torch.tensor([0.4]))
    torch.testing.assert_close(b[1:2], manual)


def test_order_of_box_names_does_not_matter(image):
    swapped = Perturbation(ParameterBox({"contrast": (0.4, 2.5), "roll_deg": (-30, 30)}))
    theta = np.array([[12.0, 1.7]])
    np.testing.assert_allclose(
        Perturbation(BOX).images(image, theta, center=CENTER), swapped.images(image, theta[:, ::-1], center=CENTER)
    )


def test_single_parameter_boxes(image):
    only_c = Perturbation(ParameterBox({"contrast": (0.5, 2)}))
    out = only_c.images_torch(image, torch.tensor([[0.5], [2.0]]))
    assert out.shape == (2, 3, *image.shape[:2])
    pts = np.array([[10.0, 20.0], [30.0, 40.0]])
    np.testing.assert_array_equal(only_c.points(pts, np.array([[0.5], [2.0]]), center=CENTER), np.stack([pts, pts]))
    only_r = Perturbation(ParameterBox({"roll_deg": (-5, 5)}))
    np.testing.assert_allclose(
        only_r.points(pts, np.array([[3.0]]), center=CENTER), roll_points(pts, np.array([3.0]), CENTER)
    )


def test_points_follow_the_image(image):
    """A dot drawn at a point ends up where Perturbation.points puts it (roll and contrast together)."""
    p = Perturbation(BOX)
    h, w = image.shape[:2]
    v, u = np.mgrid[0:h, 0:w]
    pt = np.array([[90.4, 50.2]])
    dot = np.exp(-((u - pt[0, 0]) ** 2 + (v - pt[0, 1]) ** 2) / (2 * 1.2**2))
    img = np.repeat(dot[..., None], 3, axis=2).astype(np.float32)
    theta = np.array([[-17.0, 1.5], [25.0, 0.8]])
    out = p.images(img, theta, center=CENTER)
    moved = p.points(pt, theta, center=CENTER)
    for k in range(2):
        near = (u - moved[k, 0, 0]) ** 2 + (v - moved[k, 0, 1]) ** 2 < 6.0**2
        o = np.where(near, out[k, ..., 0] - out[k, ..., 0].min(), 0.0)
        centroid = np.array([(o * u).sum(), (o * v).sum()]) / o.sum()
        assert np.linalg.norm(centroid - moved[k, 0]) < 0.02  # px (the contrast clamp flattens the peak)


def test_gradcheck_through_composer_float64(make_image):
    img = torch.from_numpy(make_image(18, 22, seed=3).astype(np.float64) / 255.0).permute(2, 0, 1)
    theta = torch.tensor([[6.3, 0.77], [-14.1, 1.9]], dtype=torch.float64, requires_grad=True)
    p = Perturbation(BOX)
    assert torch.autograd.gradcheck(lambda t: p.images_torch(img, t, center=(11.0, 9.0)), (theta,), fast_mode=True)
    pts = torch.tensor([[3.0, 4.0], [12.0, 7.0]], dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda t: p.points(pts, t, center=(11.0, 9.0)), (theta,))


def test_float32_image_with_float64_theta_backpropagates():
    p = Perturbation(BOX)
    theta = torch.tensor([[4.0, 1.2]], dtype=torch.float64, requires_grad=True)
    out = p.images_torch(torch.rand(3, 16, 16), theta)
    assert out.dtype == torch.float32
    out.sum().backward()
    assert theta.grad.dtype == torch.float64 and torch.isfinite(theta.grad).all()
