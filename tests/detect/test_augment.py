"""Appearance jitter of training images: the families' own maths, seeded, geometry untouched, train split only."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
import torch
from detect_helpers import runway_image, square_sample

from vbl_robust.detect.augment import AppearanceJitter
from vbl_robust.detect.train import build_dataset, sample_views, train
from vbl_robust.perturb.photometric import brightness
from vbl_robust.perturb.weather import haze


def _image(seed=0):
    return torch.from_numpy(runway_image(64, seed=seed)[0]).permute(2, 0, 1)[None].float() / 255.0


def test_draws_are_seeded_within_range_and_sometimes_empty():
    jit = AppearanceJitter()
    draws = [jit.draw(np.random.default_rng([5, i])) for i in range(400)]
    assert draws == [jit.draw(np.random.default_rng([5, i])) for i in range(400)]
    empty = sum(not d for d in draws)
    assert 0.4 * 400 < empty < 0.75 * 400  # p = 0.5 changed, plus changed samples that drew no family
    for d in draws:
        for name, v in d.items():
            lo, hi = getattr(jit, name)
            assert lo <= v <= hi
    seen = {name for d in draws for name in d}
    assert seen == {"blur_px", "motion_blur_px", "haze", "contrast", "brightness", "gamma", "noise_std"}
    assert not any(AppearanceJitter(p=0.0).draw(np.random.default_rng(i)) for i in range(50))


def test_apply_is_the_families_maths_in_registry_order():
    x = _image()
    only = AppearanceJitter(p=1.0, p_family=1.0, blur_px=(0, 0), motion_blur_px=(0, 0), haze=(0.25, 0.25),
                            contrast=(1, 1), brightness=(0.1, 0.1), gamma=(1, 1), noise_std=(0, 0))
    y, changes = only.apply(x, np.random.default_rng(0))
    assert changes["haze"] == 0.25 and changes["brightness"] == pytest.approx(0.1)
    one = torch.ones(1)
    torch.testing.assert_close(y, brightness(haze(x, 0.25 * one), 0.1 * one).clamp(0, 1), rtol=0, atol=1e-6)
    # noise: a fresh draw per sample (two samples differ), the same draw for the same seed
    noisy = AppearanceJitter(p=1.0, p_family=1.0, blur_px=(0, 0), motion_blur_px=(0, 0), haze=(0, 0),
                             contrast=(1, 1), brightness=(0, 0), gamma=(1, 1), noise_std=(0.05, 0.05))
    a, _ = noisy.apply(x, np.random.default_rng(1))
    b, _ = noisy.apply(x, np.random.default_rng(2))
    c, _ = noisy.apply(x, np.random.default_rng(1))
    assert torch.equal(a, c) and not torch.equal(a, b)
    assert 0.03 < float((a - x).std()) < 0.06 and 0.0 <= float(a.min()) and float(a.max()) <= 1.0


def test_views_keep_their_windows_and_labels_with_jitter():
    s = square_sample()
    strong = AppearanceJitter(p=1.0, p_family=1.0)
    plain = sample_views(s, 64, crops=2, rng=np.random.default_rng(3))
    jittered = sample_views(s, 64, crops=2, rng=np.random.default_rng(3), appearance=strong)
    assert len(plain) == len(jittered) == 3
    for (ia, ca), (ib, cb) in zip(plain, jittered, strict=True):
        np.testing.assert_array_equal(ca, cb)  # geometry untouched: same windows, same corners
        assert not np.array_equal(ia, ib)


def test_dataset_jitters_the_train_split_only_and_records_it(tmp_path):
    jit = AppearanceJitter(p=1.0, p_family=1.0)
    tr_s, va_s = [square_sample(i) for i in range(2)], [square_sample(7)]
    build_dataset(tr_s, va_s, tmp_path / "plain", imgsz=64, crops_per_sample=1, seed=1)
    build_dataset([square_sample(i) for i in range(2)], [square_sample(7)], tmp_path / "jit", imgsz=64, crops_per_sample=1,
                  seed=1, appearance=jit)
    import cv2

    def read(root, split, name):
        return cv2.imread(str(root / "images" / split / f"{name}.png"))

    assert not np.array_equal(read(tmp_path / "plain", "train", "000000_0"), read(tmp_path / "jit", "train", "000000_0"))
    np.testing.assert_array_equal(read(tmp_path / "plain", "val", "000000_0"), read(tmp_path / "jit", "val", "000000_0"))
    assert (tmp_path / "plain/labels/train/000000_1.txt").read_text() == (tmp_path / "jit/labels/train/000000_1.txt").read_text()
    assert "appearance" not in json.loads((tmp_path / "plain/build.json").read_text())
    assert json.loads((tmp_path / "jit/build.json").read_text())["appearance"]["p"] == 1.0
    with pytest.raises(ValueError, match="was built with"):
        build_dataset([square_sample(0)], [square_sample(7)], tmp_path / "jit", imgsz=64, crops_per_sample=1, seed=1)


def test_train_names_the_dataset_by_its_jitter(tmp_path, monkeypatch):
    import vbl_robust.detect.train as tr
    scenes = importlib.import_module("vbl_robust.scenes.generate")  # the module: the package's name is the function

    monkeypatch.setattr(scenes, "generate", lambda n, seed=0, **kw: [square_sample(i) for i in range(n)])
    names = []

    def stop(tr_samples, va_samples, root, **kw):
        names.append((root.name, kw["appearance"]))
        raise RuntimeError("built")

    monkeypatch.setattr(tr, "build_dataset", stop)
    for app in (None, {"p": 0.3, "haze": [0.0, 0.2]}, AppearanceJitter(p=0.3, haze=(0.0, 0.2))):
        with pytest.raises(RuntimeError, match="built"):
            train(tmp_path, n_train=4, n_val=2, imgsz=32, crops_per_sample=1, min_box=2, appearance=app)
    assert names[0] == ("dataset_32px_1crops_box2", None)
    assert names[1][0] == names[2][0] and names[1][0].startswith("dataset_32px_1crops_box2_app")
    assert names[1][1] == names[2][1] == AppearanceJitter(p=0.3, haze=(0.0, 0.2))


@pytest.mark.parametrize("bad", [dict(p=1.5), dict(haze=(0.3, 0.1)), dict(contrast=(0.0, 1.2)),
                                 dict(noise_std=(-0.1, 0.1)), dict(blur_px=(0.0, float("nan")))])
def test_bad_ranges_are_refused(bad):
    with pytest.raises(ValueError, match="AppearanceJitter"):
        AppearanceJitter(**bad)
