"""Haze and the seeded sensor noise (perturb/weather.py)."""

import numpy as np
import pytest
import torch

from vbl_robust.perturb.weather import (
    HAZE_AIRLIGHT,
    NOISE_SEED,
    GaussianNoise,
    Haze,
    gaussian_noise,
    gaussian_noise_numpy,
    haze,
    haze_numpy,
    noise_pattern,
    noise_pattern_tensor,
)


def test_haze_is_the_airlight_blend(image):
    f = image.astype(np.float32) / 255.0
    x = torch.from_numpy(f).permute(2, 0, 1)[None]
    h = torch.tensor([0.0, 0.3, 1.0])
    out = haze(x, h)
    for i, a in enumerate(h.tolist()):
        np.testing.assert_allclose(out[i].permute(1, 2, 0).numpy(), (1 - a) * f + a * HAZE_AIRLIGHT, atol=1e-6)
        np.testing.assert_allclose(haze_numpy(f, a), (1 - a) * f + a * HAZE_AIRLIGHT, atol=1e-6)
    assert torch.equal(out[0:1], x) and torch.allclose(out[2], torch.full_like(out[2], HAZE_AIRLIGHT))
    torch.testing.assert_close(Haze()(x, h), out)


def test_noise_pattern_is_fixed_and_seeded():
    a = noise_pattern(40, 50)
    assert a.shape == (40, 50, 3) and a.dtype == np.float32 and not a.flags.writeable
    assert np.array_equal(a, np.random.default_rng(NOISE_SEED).standard_normal((40, 50, 3), dtype=np.float32))
    assert np.array_equal(noise_pattern(40, 50), a)
    assert not np.array_equal(noise_pattern(40, 50, seed=1), a)
    assert abs(float(a.std()) - 1.0) < 0.05 and abs(float(a.mean())) < 0.05
    # a source resized to half: the sensor's pattern area-averaged (its std halves for 2 x 2 averaging)
    half = noise_pattern(20, 25, base_size=(50, 40))
    np.testing.assert_allclose(half, a.reshape(20, 2, 25, 2, 3).mean(axis=(1, 3)), atol=1e-6)
    assert 0.4 < float(half.std()) < 0.6
    assert noise_pattern(40, 50, 1).shape == (40, 50, 1)
    assert noise_pattern_tensor(40, 50).shape == (3, 40, 50)


def test_noise_is_deterministic_continuous_and_clamped(image):
    f = image.astype(np.float32) / 255.0
    pat = noise_pattern(*f.shape)
    x = torch.from_numpy(f).permute(2, 0, 1)[None]
    pt = torch.from_numpy(np.array(pat)).permute(2, 0, 1)
    s = torch.tensor([0.0, 0.05, 0.05 + 1e-6, 0.5])
    out = gaussian_noise(x, s, pt)
    assert torch.equal(out[0:1], x) and torch.equal(gaussian_noise(x, s, pt), out)
    assert (out[2] - out[1]).abs().max() <= 1e-6 * float(np.abs(pat).max()) + 1e-6  # continuous in the amplitude
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    np.testing.assert_allclose(gaussian_noise_numpy(f, 0.05, pat), out[1].permute(1, 2, 0).numpy(), atol=1e-6)
    interior = (f > 0.2) & (f < 0.8)
    assert abs(float((out[1].permute(1, 2, 0).numpy() - f)[interior].std()) - 0.05) < 0.005
    torch.testing.assert_close(GaussianNoise()(x.expand(4, -1, -1, -1), s), out)


def test_gradcheck_amounts_float64(make_image):
    img = torch.from_numpy(make_image(12, 15, seed=5).astype(np.float64) / 255.0).permute(2, 0, 1)[None]
    h = torch.tensor([0.21, 0.74], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: haze(img, a), (h,), fast_mode=True)
    pat = torch.from_numpy(np.array(noise_pattern(12, 15))).permute(2, 0, 1).double()
    s = torch.tensor([0.013, 0.061], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a: gaussian_noise(img, a, pat), (s,), fast_mode=True)


def test_errors():
    with pytest.raises(ValueError, match="pattern"):
        gaussian_noise(torch.zeros(1, 3, 4, 4), torch.tensor([0.1]), torch.zeros(3, 5, 4))
    with pytest.raises(ValueError, match="2 images for 3"):
        haze(torch.zeros(2, 3, 4, 4), torch.zeros(3))
    with pytest.raises(ValueError, match="channels"):
        noise_pattern(4, 4, 2)
