"""Gaussian and motion blur (perturb/optical.py): OpenCV agreement, continuity, batch independence, gradients."""

import cv2
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from vbl_robust.perturb.optical import (
    GaussianBlur,
    MotionBlur,
    gaussian_blur,
    gaussian_blur_numpy,
    gaussian_kernel1d,
    gaussian_radius,
    motion_blur,
    motion_blur_numpy,
    motion_kernel1d,
    motion_radius,
)


def _t(img: np.ndarray, dtype=torch.float32) -> torch.Tensor:
    return torch.from_numpy(img.astype(np.float64) / 255.0).permute(2, 0, 1)[None].to(dtype)


def _hwc(t: torch.Tensor) -> np.ndarray:
    return t[0].permute(1, 2, 0).double().numpy()


@pytest.mark.parametrize("sigma", [0.3, 0.8, 1.0, 2.5, 4.0])
def test_gaussian_blur_agrees_with_cv2_gaussian_blur(image, sigma):
    f = image.astype(np.float32) / 255.0
    ref = cv2.GaussianBlur(f, (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)
    ours = gaussian_blur_numpy(f, sigma)
    # the taper at 4σ (module Convention): within 1e-3 of full scale (a quarter grey level), 3e-4 for σ ≥ 1
    assert np.abs(ours - ref).max() < (3e-4 if sigma >= 1 else 1e-3)
    assert np.abs(_hwc(gaussian_blur(_t(image), torch.tensor([sigma]))) - ours).max() < 1e-6  # the same kernel


@pytest.mark.parametrize("length", [3, 5, 9])
def test_motion_blur_of_odd_integer_length_is_opencvs_box_filter(image, length):
    f = image.astype(np.float32) / 255.0
    ref = cv2.blur(f, (length, 1), borderType=cv2.BORDER_REFLECT_101)  # horizontal box of `length` pixels
    assert np.abs(motion_blur_numpy(f, float(length)) - ref).max() < 1e-6
    assert np.abs(_hwc(motion_blur(_t(image), torch.tensor([float(length)]))) - ref).max() < 1e-6


def test_kernels_sum_to_one_and_small_lengths_are_the_identity(image):
    for s in (0.0, 0.25, 0.7, 3.3):
        k = gaussian_kernel1d(np.array([s]), gaussian_radius(s))
        assert k.sum() == pytest.approx(1.0) and k.shape[1] == 2 * gaussian_radius(s) + 1 and (k > 0).all()
    for n in (0.0, 1.0, 2.2, 7.9):
        k = motion_kernel1d(np.array([n]), motion_radius(n))
        assert k.sum() == pytest.approx(1.0) and (k > 0).all()
    x = _t(image)
    assert torch.equal(gaussian_blur(x, torch.tensor([0.0, 0.25])), x.expand(2, -1, -1, -1))
    assert torch.equal(motion_blur(x, torch.tensor([0.0, 1.0])), x.expand(2, -1, -1, -1))
    f = image.astype(np.float32) / 255.0
    assert np.array_equal(gaussian_blur_numpy(f, 0.2), f) and np.array_equal(motion_blur_numpy(f, 0.5), f)


@settings(max_examples=30, deadline=None)
@given(s=st.floats(0.0, 6.0), which=st.sampled_from(["gauss", "motion"]))
def test_blur_is_continuous_in_its_length(s, which):
    """Where a new tap enters the kernel (4σ or (L + 1)/2 passes an integer) the image does not jump."""
    x = torch.from_numpy(np.random.default_rng(0).random((1, 1, 12, 40)))
    f = gaussian_blur if which == "gauss" else motion_blur
    scale = 1.0 if which == "gauss" else 6.0
    a = f(x, torch.tensor([s * scale], dtype=torch.float64))
    b = f(x, torch.tensor([s * scale + 1e-7], dtype=torch.float64))
    assert (a - b).abs().max() < 1e-5


def test_rows_do_not_depend_on_the_rest_of_the_batch(image):
    x = _t(image)
    sig = torch.tensor([0.7, 3.1, 0.0, 1.4])
    both = gaussian_blur(x, sig)
    for i in range(4):
        assert torch.equal(both[i : i + 1], gaussian_blur(x, sig[i : i + 1]))
    ln = torch.tensor([2.5, 11.0, 0.0])
    both = motion_blur(x, ln)
    for i in range(3):
        assert torch.equal(both[i : i + 1], motion_blur(x, ln[i : i + 1]))


def test_anisotropic_sigma_and_constants(image):
    x = _t(image, torch.float64)
    only_x = gaussian_blur(x, torch.tensor([[2.0, 0.0]]))
    f = image.astype(np.float64) / 255.0
    assert np.abs(_hwc(only_x) - gaussian_blur_numpy(f, 2.0, 0.0)).max() < 1e-12
    flat = torch.full((1, 3, 9, 11), 0.3, dtype=torch.float64)
    assert torch.allclose(gaussian_blur(flat, torch.tensor([5.0])), flat, atol=1e-15)  # reflection keeps constants
    assert torch.allclose(motion_blur(flat, torch.tensor([7.5])), flat, atol=1e-15)


def test_gradcheck_lengths_float64(make_image):
    img = torch.from_numpy(make_image(14, 17, seed=4).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    sig = torch.tensor([0.83, 1.61], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda s: gaussian_blur(img, s), (sig,), eps=1e-6, atol=1e-6, fast_mode=True)
    ln = torch.tensor([2.4, 4.7], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda n: motion_blur(img, n), (ln,), eps=1e-6, atol=1e-6, fast_mode=True)


def test_modules_and_errors(image):
    x = _t(image)
    torch.testing.assert_close(GaussianBlur()(x, torch.tensor([1.2])), gaussian_blur(x, torch.tensor([1.2])))
    torch.testing.assert_close(MotionBlur()(x, torch.tensor([3.2])), motion_blur(x, torch.tensor([3.2])))
    with pytest.raises(ValueError, match="images must have shape"):
        gaussian_blur(x[0], torch.tensor([1.0]))
    with pytest.raises(ValueError, match="2 images for 3"):
        motion_blur(x.expand(2, -1, -1, -1), torch.ones(3))
    with pytest.raises(ValueError, match="sigma_x must be finite and >= 0"):
        gaussian_blur_numpy(image.astype(np.float32), -1.0)
    with pytest.raises(ValueError, match="length_px"):
        motion_blur_numpy(image.astype(np.float32), float("inf"))
