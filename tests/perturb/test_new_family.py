"""A new perturbation family is one module with its maps plus one registry line: shown with a family defined here.

The family (a vignette: the image darkens towards its corners by a factor ``1 - s r²``) lives in this test module;
its registry line is added for the test only. Nothing else is touched, and it works through the NumPy and torch
composers, the view sampler (direct and framed), the point map and the training augmentation.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.family import Family
from vbl_robust.perturb.registry import PERTURBATIONS, PerturbationSpec
from vbl_robust.perturb.views import ViewSampler, resample, to_tensor
from vbl_robust.space import ParameterBox


def _falloff(h: int, w: int) -> np.ndarray:
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return (((u - (w - 1) / 2) / w) ** 2 + ((v - (h - 1) / 2) / h) ** 2) * 2.0  # 1 at the corners


class _Vignette(Family):
    params = ("vignette",)

    def frame_numpy(self, frame, v, ctx, out):
        h, w = frame.shape[:2]
        gain = (1.0 - v["vignette"] * _falloff(h, w)).astype(np.float32)[..., None]
        return np.multiply(frame, gain, out=out)

    def frame_torch(self, x, v, ctx):
        h, w = x.shape[-2:]
        r2 = torch.from_numpy(_falloff(h, w)).to(x.device, x.dtype)
        return x * (1.0 - v["vignette"].to(x.dtype)[:, None, None, None] * r2)


VIGNETTE = _Vignette()

SPEC = PerturbationSpec("vignette", "optical", 0.0, 0.0, "corner darkening 1 - s r², s in [0, 1]", maximum=1.0,
                        unit="fraction", default=(0.0, 0.5), levels=((0, 0.1), (0, 0.2), (0, 0.4), (0, 0.6), (0, 0.8)),
                        rationale="test family", family=f"{__name__}:VIGNETTE")


@pytest.fixture
def registered():
    """The one line: the registry entry, after the optics and before the photometry (for this test only)."""
    saved = list(PERTURBATIONS.items())
    at = [n for n, _ in saved].index("haze")
    PERTURBATIONS.clear()
    PERTURBATIONS.update([*saved[:at], ("vignette", SPEC), *saved[at:]])
    try:
        yield
    finally:
        PERTURBATIONS.clear()
        PERTURBATIONS.update(saved)


def test_unknown_until_registered():
    with pytest.raises(ValueError, match="unknown parameter 'vignette'"):
        Perturbation(["vignette"])


def test_the_new_family_runs_everywhere(registered, image):
    box = ParameterBox({"roll_deg": (-10, 10), "vignette": (0.0, 0.6), "contrast": (0.7, 1.4)})
    p = Perturbation(box)
    assert p.needs_frame and not p.needs_K  # an optical family: views come from whole frames
    theta = np.array([[0.0, 0.0, 1.0], [0.0, 0.6, 1.0], [7.0, 0.4, 1.3]])
    a = p.images_numpy(image, theta)
    b = p.images_torch(image, torch.from_numpy(theta)).permute(0, 2, 3, 1).numpy()
    assert np.abs(a - b).max() < 2e-4
    np.testing.assert_array_equal(a[0], image.astype(np.float32) / 255.0)  # the identity is exact
    corner, centre = a[1, 0, 0] / (image[0, 0] / 255.0 + 1e-9), a[1, 60, 80] / (image[60, 80] / 255.0 + 1e-9)
    assert float(corner.mean()) < 0.6 and float(centre.mean()) > 0.95  # darkened where the family says
    # applied in the registry's order: after the roll, before the contrast
    rolled = Perturbation(["roll_deg"]).images_numpy(image, theta[2:, :1])
    manual = VIGNETTE.frame_numpy(rolled[0].copy(), {"vignette": 0.4}, None, rolled[0].copy())
    manual = Perturbation(["contrast"]).images_numpy(manual, theta[2:, 2:])
    np.testing.assert_allclose(a[2], manual[0], atol=1e-6)
    # the view sampler cuts views from the frames; points move with the roll only
    s = ViewSampler(p, to_tensor(image), theta, center=(80.0, 60.0))
    wins = torch.tensor([[10.0, 5.0, 100.0]] * 3)
    assert torch.equal(s.views(wins, 32), resample(s.frames(), wins, 32))
    pts = p.points(np.array([[80.0, 60.0], [100.0, 60.0]]), theta, center=(80.0, 60.0))
    np.testing.assert_allclose(pts[1], [[80.0, 60.0], [100.0, 60.0]], atol=1e-12)


def test_the_training_augmentation_reads_the_registry(registered, image):
    from dataclasses import make_dataclass

    from vbl_robust.detect.augment import AppearanceJitter

    assert "vignette" not in AppearanceJitter.families()  # a family joins training by a range field
    Jitter = make_dataclass("Jitter", [("vignette", tuple, (0.5, 0.5))], bases=(AppearanceJitter,), frozen=True)
    jit = Jitter(p=1.0, p_family=1.0, blur_px=(0, 0), motion_blur_px=(0, 0), haze=(0, 0), contrast=(1, 1),
                 brightness=(0, 0), gamma=(1, 1), noise_std=(0, 0))
    assert jit.families()[:3] == ("blur_px", "motion_blur_px", "vignette")
    x = to_tensor(image)
    y, changes = jit.apply(x, np.random.default_rng(0))
    assert changes["vignette"] == 0.5
    ref = Perturbation(["vignette"]).images_torch(x, torch.tensor([[0.5]], dtype=torch.float64))
    torch.testing.assert_close(y, ref.to(y.dtype).clamp(0, 1), rtol=0, atol=1e-6)
