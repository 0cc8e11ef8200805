import numpy as np
import pytest
import torch
import torchvision.transforms.functional as TF

from vbl_robust.perturb.photometric import (
    Brightness,
    Contrast,
    Gamma,
    brightness,
    brightness_numpy,
    contrast,
    contrast_numpy,
    gamma,
    gamma_numpy,
)


@pytest.mark.parametrize("factor", [0.0, 0.4, 0.93, 1.0, 1.4, 2.5])
def test_contrast_equals_torchvision_on_float_images(image, factor):
    x = torch.from_numpy(image).permute(2, 0, 1).float()[None] / 255.0
    ours = contrast(x, torch.tensor([factor]))
    ref = TF.adjust_contrast(x[0], factor)
    torch.testing.assert_close(ours[0], ref, atol=2e-6, rtol=0)  # float32 summation order only


def test_contrast_batched_broadcast_and_numpy_twin(image):
    x = torch.from_numpy(image).permute(2, 0, 1).double()[None] / 255.0
    factors = torch.tensor([0.4, 1.0, 2.5], dtype=torch.float64)
    out = contrast(x, factors)
    assert out.shape == (3, *x.shape[1:])
    torch.testing.assert_close(out[1:2], x)  # 1 is the identity
    for k, f in enumerate(factors.tolist()):
        torch.testing.assert_close(out[k], TF.adjust_contrast(x[0], f))
        np.testing.assert_allclose(
            contrast_numpy(image.astype(np.float32) / 255.0, f), out[k].permute(1, 2, 0).numpy(), atol=1e-6
        )
    assert out.min() >= 0.0 and out.max() <= 1.0
    torch.testing.assert_close(Contrast()(x, factors), out)


def test_zero_contrast_is_uniform_grayscale_mean(image):
    x = torch.from_numpy(image).permute(2, 0, 1).double()[None] / 255.0
    grey = contrast(x, torch.tensor([0.0], dtype=torch.float64))
    mean = (0.2989 * x[0, 0] + 0.587 * x[0, 1] + 0.114 * x[0, 2]).mean()
    torch.testing.assert_close(grey, torch.full_like(x, float(mean)))


def test_single_channel_uses_channel_mean():
    x = torch.tensor([0.2, 0.4, 0.6], dtype=torch.float64).view(1, 1, 1, 3)
    torch.testing.assert_close(contrast(x, torch.tensor([0.5])), TF.adjust_contrast(x[0], 0.5)[None])


def test_gradcheck_factor_float64(make_image):
    img = torch.from_numpy(make_image(20, 24, seed=2).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    factors = torch.tensor([0.61, 1.37, 2.2], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda f: contrast(img, f), (factors,), fast_mode=True)
    # the gradient is not trivially zero
    factors.grad = None
    contrast(img, factors).sum().backward()
    assert torch.all(factors.grad.abs() > 0)


def test_errors():
    with pytest.raises(ValueError, match="images must have shape"):
        contrast(torch.rand(1, 2, 4, 4), torch.tensor([1.0]))
    with pytest.raises(ValueError, match="floating point"):
        contrast(torch.zeros(1, 3, 4, 4, dtype=torch.uint8), torch.tensor([1.0]))
    with pytest.raises(ValueError, match="2 images for 3 factors"):
        contrast(torch.rand(2, 3, 4, 4), torch.tensor([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="image must have shape"):
        contrast_numpy(np.zeros((4, 4)), 1.0)


@pytest.mark.parametrize("offset", [-0.5, -0.07, 0.0, 0.13, 0.4])
def test_brightness_is_a_clamped_offset_and_matches_torchvision(image, offset):
    f = image.astype(np.float32) / 255.0
    x = torch.from_numpy(f).permute(2, 0, 1)[None]
    out = brightness(x, torch.tensor([offset]))
    np.testing.assert_allclose(out[0].permute(1, 2, 0).numpy(), np.clip(f + offset, 0, 1), atol=1e-7)
    np.testing.assert_allclose(brightness_numpy(f, offset), np.clip(f + offset, 0, 1), atol=1e-7)
    torch.testing.assert_close(Brightness()(x, torch.tensor([offset])), out)


@pytest.mark.parametrize("exponent", [0.4, 0.8, 1.0, 1.7, 2.5])
def test_gamma_equals_torchvision_adjust_gamma(image, exponent):
    x = torch.from_numpy(image).permute(2, 0, 1).float()[None] / 255.0
    ours = gamma(x, torch.tensor([exponent]))
    torch.testing.assert_close(ours[0], TF.adjust_gamma(x[0], exponent), atol=1e-6, rtol=0)
    np.testing.assert_allclose(gamma_numpy(image.astype(np.float32) / 255.0, exponent),
                               ours[0].permute(1, 2, 0).numpy(), atol=1e-6)
    torch.testing.assert_close(Gamma()(x, torch.tensor([exponent])), ours)


def test_brightness_and_gamma_broadcast_over_rows_and_views(image):
    x = torch.from_numpy(image).permute(2, 0, 1).double()[None] / 255.0
    assert brightness(x, torch.tensor([0.1, 0.2])).shape == (2, *x.shape[1:])
    values = torch.rand(3, 3, 5, 7, dtype=torch.float64)  # view samples: (B, 3, ny, nx)
    torch.testing.assert_close(gamma(values, torch.tensor([1.0, 2.0, 0.5]))[1], values[1] ** 2)
    torch.testing.assert_close(gamma(x, torch.tensor([1.0])), x)
    with pytest.raises(ValueError, match=">= 0"):
        gamma(x, torch.tensor([-0.5]))
    with pytest.raises(ValueError, match="2 factors"):
        brightness(torch.rand(3, 3, 4, 4), torch.tensor([0.1, 0.2]))


def test_gradcheck_brightness_and_gamma_float64(make_image):
    img = torch.from_numpy(make_image(20, 24, seed=2).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    offs = torch.tensor([-0.13, 0.21], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda b: brightness(img, b), (offs,), fast_mode=True)
    exps = torch.tensor([0.57, 1.83], dtype=torch.float64, requires_grad=True)
    black = img.clone()
    black[..., :3, :3] = 0.0  # black pixels: the gradient in the exponent stays finite there
    assert torch.autograd.gradcheck(lambda g: gamma(black, g), (exps,), fast_mode=True)
