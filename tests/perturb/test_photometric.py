import numpy as np
import pytest
import torch
import torchvision.transforms.functional as TF

from vbl_robust.perturb import Contrast, contrast, contrast_numpy


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
