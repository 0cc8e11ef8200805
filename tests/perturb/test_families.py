"""Every registered family through the composer and the view sampler: one contract, run over the registry."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vbl_robust.detect.windows import letterbox_window
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.family import Family
from vbl_robust.perturb.optical import gaussian_blur, motion_blur
from vbl_robust.perturb.photometric import brightness, contrast, gamma
from vbl_robust.perturb.registry import KINDS, PERTURBATIONS, family_of
from vbl_robust.perturb.resample import PixelScale, resize_image
from vbl_robust.perturb.rotation import attitude
from vbl_robust.perturb.views import ViewSampler, resample, to_tensor
from vbl_robust.perturb.weather import gaussian_noise, haze, noise_pattern_tensor
from vbl_robust.space import KNOWN_UNITS, ParameterBox

NAMES = list(PERTURBATIONS)
#: a strong but plausible value of each family (level 3 to 4)
STRONG = {"roll_deg": 12.0, "pitch_deg": 6.0, "yaw_deg": -8.0, "blur_px": 1.7, "motion_blur_px": 5.5, "haze": 0.4,
          "contrast": 1.6, "brightness": 0.15, "gamma": 0.6, "noise_std": 0.05}
K_SMALL = np.array([[140.0, 0.0, 83.0], [0.0, 140.0, 57.5], [0.0, 0.0, 1.0]])  # for the 160 x 120 test image


def test_registry_contract():
    assert set(STRONG) == set(NAMES)
    for name, spec in PERTURBATIONS.items():
        assert spec.name == name and spec.kind in KINDS and spec.description and spec.rationale
        assert spec.unit == KNOWN_UNITS[name]
        assert spec.minimum <= spec.identity <= spec.maximum
        lo, hi = spec.default
        assert spec.minimum <= lo <= spec.identity <= hi <= spec.maximum and lo < hi
        assert len(spec.levels) == 5
        prev = (spec.identity, spec.identity)
        for a, b in spec.levels:  # nested, mild to extreme, inside the family's domain
            assert spec.minimum <= a <= prev[0] and prev[1] <= b <= spec.maximum and (a, b) != prev
            prev = (a, b)
        Perturbation(ParameterBox({name: spec.levels[-1]}))  # the extreme level is a valid box
        fam = family_of(name)  # its maps: one Family object, shared by the parameters it reads
        assert isinstance(fam, Family) and name in fam.params and set(fam.needs_K) <= set(fam.params)
        if spec.kind == "photometric":
            assert type(fam).pointwise is not Family.pointwise
        if spec.kind == "geometric":
            assert type(fam).points is not Family.points and type(fam).source_coords is not Family.source_coords


@pytest.mark.parametrize("name", NAMES)
def test_numpy_and_torch_paths_agree_and_identity_is_exact(image, name):
    p = Perturbation([name])
    ident = PERTURBATIONS[name].identity
    theta = np.array([[STRONG[name]], [ident], [0.5 * (STRONG[name] + ident)]])
    a = p.images_numpy(image, theta, K=K_SMALL)
    b = p.images_torch(image, torch.from_numpy(theta), K=K_SMALL).permute(0, 2, 3, 1).numpy()
    tol = 1e-4 if PERTURBATIONS[name].kind == "geometric" else 1e-5  # warps: float32 coordinates / OpenCV
    assert np.abs(a - b).max() < tol
    assert np.array_equal(a[1], image / np.float32(255.0))
    assert np.abs(b[1] - image / 255.0).max() < 2e-5
    assert np.abs(a[0] - a[1]).max() > 0.01  # and the strong value changes the image


@pytest.mark.parametrize("name", NAMES)
def test_gradcheck_through_the_composer_float64(make_image, name):
    img = torch.from_numpy(make_image(14, 18, seed=3).astype(np.float64) / 255.0).permute(2, 0, 1)
    k = np.array([[16.0, 0.0, 9.2], [0.0, 16.0, 6.9], [0.0, 0.0, 1.0]])
    p = Perturbation([name])
    v = STRONG[name] * 0.77 + 0.013
    theta = torch.tensor([[v], [0.5 * v + 0.5 * PERTURBATIONS[name].identity + 0.011]], dtype=torch.float64,
                         requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: p.images_torch(img, t, K=k), (theta,), eps=1e-6, atol=1e-5,
                                    fast_mode=True)
    p.images_torch(img, theta, K=k).sum().backward()
    assert float(theta.grad.abs().min()) > 0  # not trivially zero
    pts = torch.tensor([[3.0, 4.0], [12.0, 7.0]], dtype=torch.float64)
    moved = p.points(pts, theta, K=k)
    if PERTURBATIONS[name].kind == "geometric":
        assert torch.autograd.gradcheck(lambda t: p.points(pts, t, K=k), (theta,))
    else:
        assert torch.equal(moved, pts.expand(2, -1, -1))  # only the geometry moves points


def test_the_documented_order_of_application(image):
    """All ten families at once equal the functions composed in the order of the registry."""
    p = Perturbation(ParameterBox({n: (PERTURBATIONS[n].levels[-1]) for n in reversed(NAMES)}))  # order-free box
    row = torch.tensor([[STRONG[n] for n in p.names]], dtype=torch.float64)
    x = torch.from_numpy(image).permute(2, 0, 1)[None].double() / 255.0
    scale = PixelScale(0.5, 0.5)
    got = p.images_torch(x, row, K=K_SMALL, scale=scale)
    v = {n: torch.tensor([STRONG[n]], dtype=torch.float64) for n in NAMES}
    y = attitude(x, v["roll_deg"], v["pitch_deg"], v["yaw_deg"], K_SMALL)
    y = gaussian_blur(y, v["blur_px"] * 0.5)
    y = motion_blur(y, v["motion_blur_px"] * 0.5)
    y = gamma(brightness(contrast(haze(y, v["haze"]), v["contrast"]), v["brightness"]), v["gamma"])
    y = gaussian_noise(y, v["noise_std"], noise_pattern_tensor(120, 160, base_size=(320, 240)))
    torch.testing.assert_close(got, y)
    np.testing.assert_allclose(p.images_numpy(image, row.numpy(), K=K_SMALL, scale=scale)[0],
                               got[0].permute(1, 2, 0).numpy(), atol=1e-4)


def test_blur_lengths_are_in_the_samples_pixels(image):
    """Blurring the resized image with the scale ≈ blurring the full image, then resizing."""
    f = image.astype(np.float32) / 255.0
    small = resize_image(f, (80, 60))
    for name, value in (("blur_px", 4.0), ("motion_blur_px", 10.0)):
        p = Perturbation([name])
        first = resize_image(p.images_numpy(f, np.array([[value]]))[0], (80, 60))
        after = p.images_numpy(small, np.array([[value]]), scale=PixelScale(0.5, 0.5))[0]
        unscaled = p.images_numpy(small, np.array([[value]]))[0]
        assert np.abs(first - after).mean() < 0.25 * np.abs(first - unscaled).mean()


@pytest.fixture(scope="module")
def scene():
    from vbl_robust.scenes.generate import generate

    return generate(1, seed=5, width=384, height=384)[0]


POINTWISE_AND_GEOMETRIC = tuple(n for n in NAMES if PERTURBATIONS[n].kind in ("geometric", "photometric"))


@pytest.mark.parametrize("names", [(n,) for n in NAMES] + [POINTWISE_AND_GEOMETRIC, tuple(NAMES)], ids=str)
def test_views_are_crops_of_the_perturbed_frames_for_every_family(scene, names):
    """auto (direct for pointwise and geometric families, frames first for optical and noise) against resampling
    the whole perturbed frames: identical for the identity and for optical/noise families, within interpolation
    smoothing otherwise (the tolerances of the roll and contrast sampler test)."""
    img = to_tensor(scene.image)
    h, w = scene.image.shape[:2]
    p = Perturbation(names)
    ident = np.array([PERTURBATIONS[n].identity for n in names])
    strong = np.array([STRONG[n] for n in names])
    theta = np.array([ident, strong, 0.5 * (ident + strong)] * 3)
    # a letterbox that pools by 2 (384 → 160), a zoomed-in crop, a crop over the top-right corner (reflection + padding)
    wins = torch.tensor([letterbox_window(h, w)] * 3 + [(150.0, 230.0, 60.0)] * 3 + [(w - 80.0, -30.0, 140.0)] * 3)
    for th in (theta, torch.from_numpy(theta)):
        s = ViewSampler(p, img, th, K=scene.K)
        auto = s.views(wins, 160)
        ref = resample(s.frames(), wins, 160)
        d = (auto - ref).abs().detach()
        if p.needs_frame:
            assert torch.equal(auto, ref)
            with pytest.raises(ValueError, match="whole frames"):
                s.views(wins, 160, strategy="direct")
            continue
        assert float(d[[0, 3]].max()) < 1e-4  # the identity: the same views (inside the image)
        assert float(d.mean(dim=(1, 2, 3)).max()) < 0.01, d.mean(dim=(1, 2, 3))
        assert float(d[6:].mean()) < 0.004  # the corner crop: reflection and padding where the frames put them


def test_direct_views_of_every_family_at_once_are_differentiable(scene):
    names = [n for n in NAMES if PERTURBATIONS[n].kind in ("geometric", "photometric")]
    p = Perturbation(names)
    theta = torch.tensor([[STRONG[n] for n in names]], dtype=torch.float64, requires_grad=True)
    s = ViewSampler(p, to_tensor(scene.image), theta, K=scene.K)
    v = s.views(torch.tensor([[100.0, 150.0, 120.0]]), 48, strategy="direct")
    v.sum().backward()
    assert torch.isfinite(theta.grad).all() and (theta.grad != 0).all()
    # and the frame path with the optical and noise families
    q = Perturbation(NAMES)
    theta = torch.tensor([[STRONG[n] for n in NAMES]], dtype=torch.float64, requires_grad=True)
    s = ViewSampler(q, to_tensor(scene.image), theta, K=scene.K)
    s.views(torch.tensor([[100.0, 150.0, 120.0]]), 48).sum().backward()
    assert torch.isfinite(theta.grad).all() and (theta.grad != 0).all()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_combination_is_a_box_and_both_paths_agree(make_image, data):
    image = make_image()  # a pure factory: the same image for every example
    names = data.draw(st.lists(st.sampled_from(NAMES), min_size=1, max_size=len(NAMES), unique=True))
    box = ParameterBox({n: PERTURBATIONS[n].levels[2] for n in names})
    p = Perturbation(box)
    u = np.array(data.draw(st.lists(st.floats(0.0, 1.0), min_size=box.dim, max_size=box.dim)))
    theta = box.from_unit(u[None])
    a = p.images_numpy(image, theta, K=K_SMALL)
    b = p.images_torch(image, torch.from_numpy(theta), K=K_SMALL).permute(0, 2, 3, 1).numpy()
    assert a.shape == (1, *image.shape) and np.abs(a - b).max() < 2e-4
    pts = np.array([[10.0, 20.0], [150.0, 110.0]])
    moved = p.points(pts, theta, K=K_SMALL)
    assert moved.shape == (1, 2, 2) and np.isfinite(moved).all()
    if not p.is_geometric:
        np.testing.assert_array_equal(moved[0], pts)
