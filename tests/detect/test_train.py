"""Training: dataset rendering (labels follow the views), offline run, resume → new cumulative stage."""

from __future__ import annotations

import numpy as np
import pytest
from detect_helpers import runway_image

from vbl_robust.data.sample import Sample
from vbl_robust.data.yolo import parse_pose_label
from vbl_robust.detect.train import build_dataset, sample_views, train
from vbl_robust.geometry.camera import intrinsics


def _samples(n, size=96):
    out = []
    for i in range(n):
        img, c = runway_image(size, seed=i)
        out.append(Sample(id=f"s{i}", K=intrinsics(size, size), corners_3d=np.zeros((4, 3)), corners_2d=c,
                          position=np.array([-1000.0, 0.0, 50.0]), width=size, height=size, _image=img))
    return out


def test_views_and_labels_follow_the_image(tmp_path):
    s = _samples(1)[0]
    views = sample_views(s, 64, crops=3, rng=np.random.default_rng(0))
    assert len(views) == 4
    for img, c in views:
        assert img.shape == (64, 64, 3) and img.dtype == np.uint8
        # the runway trapezoid is bright: the pixel at the centre of its corners is bright in every view
        m = np.round(c.mean(0)).astype(int)
        assert img[m[1], m[0]].mean() > 150
    data = build_dataset(_samples(3), _samples(2), tmp_path / "ds", imgsz=64, crops_per_sample=2, seed=1)
    labels = sorted((tmp_path / "ds/labels/train").glob("*.txt"))
    assert len(labels) == 9 and len(list((tmp_path / "ds/labels/val").glob("*.txt"))) == 4
    _, corners, vis = parse_pose_label(labels[0].read_text(), 64, 64)
    assert vis.all() and np.isfinite(corners).all()
    assert data.name == "data.yaml"


def test_train_offline_and_resume(tmp_path, monkeypatch):
    import socket

    def no_network(*a, **k):
        raise OSError("network disabled in this test")

    monkeypatch.setattr(socket, "getaddrinfo", no_network)
    monkeypatch.setattr(socket.socket, "connect", no_network)
    r = train(tmp_path / "run", samples=_samples(8), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, seed=0)
    assert r.best.exists() and r.stage_dir.name == "stage00"
    with pytest.raises(ValueError, match="resume"):
        train(tmp_path / "run", samples=_samples(8), imgsz=64, epochs=1)
    r2 = train(tmp_path / "run", samples=_samples(8), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, resume=True)
    assert r2.stage_dir.name == "stage01" and r2.best.exists()  # a finished stage continues as a new stage


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="detector"):
        train(tmp_path, samples=_samples(3), detector="three")
    with pytest.raises(ValueError, match="imgsz"):
        train(tmp_path, samples=_samples(3), imgsz=100)
