"""Training: dataset rendering (labels follow the views), offline run, resume → new cumulative stage."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from detect_helpers import square_sample

from vbl_robust.data.sample import Sample
from vbl_robust.data.yolo import parse_pose_label
from vbl_robust.detect.train import build_dataset, sample_views, train
from vbl_robust.geometry.camera import intrinsics


def _samples(n, size=96):
    return [square_sample(i, size) for i in range(n)]


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
    # min_box: every labelled box at least that wide, recorded in the build spec (another value → other dir)
    build_dataset(_samples(3), _samples(2), tmp_path / "ds24", imgsz=64, crops_per_sample=0, seed=1, min_box=24)
    for f in (tmp_path / "ds24/labels/train").glob("*.txt"):
        box, _, _ = parse_pose_label(f.read_text(), 64, 64)
        assert min(box[2] - box[0], box[3] - box[1]) >= 24 - 1e-4 or box[0] == 0 or box[2] == 64
    with pytest.raises(ValueError, match="min_box"):
        build_dataset(_samples(3), _samples(2), tmp_path / "ds24", imgsz=64, crops_per_sample=0, seed=1)


def test_train_offline_and_resume(tmp_path, monkeypatch):
    import socket

    def no_network(*a, **k):
        raise OSError("network disabled in this test")

    monkeypatch.setattr(socket, "getaddrinfo", no_network)
    monkeypatch.setattr(socket.socket, "connect", no_network)
    import torch

    before = torch.get_num_threads()
    try:
        # ultralytics alone would use cpu_count − 1 threads (1 on a 2-core machine); `threads` wins
        r = train(tmp_path / "run", samples=_samples(8), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, seed=0,
                  threads=3)
        assert torch.get_num_threads() == 3
    finally:
        torch.set_num_threads(before)
    assert r.best.exists() and r.stage_dir.name == "stage00"
    with pytest.raises(ValueError, match="resume"):
        train(tmp_path / "run", samples=_samples(8), imgsz=64, epochs=1)
    # resuming loads the stage's checkpoints (pickles): refused without the caller's trust (issue 48 item 3)
    with pytest.raises(ValueError, match="pass --trust-model if you trust them"):
        train(tmp_path / "run", samples=_samples(8), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, resume=True)
    r2 = train(tmp_path / "run", samples=_samples(8), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, resume=True,
               trust_checkpoints=True)
    assert r2.stage_dir.name == "stage01" and r2.best.exists()  # a finished stage continues as a new stage


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="detector"):
        train(tmp_path, samples=_samples(3), detector="three")
    with pytest.raises(ValueError, match="imgsz"):
        train(tmp_path, samples=_samples(3), imgsz=100)
    with pytest.raises(ValueError, match="n_airports"):
        train(tmp_path, n_train=4, n_val=2, n_airports=0)


def test_synthetic_data_uses_the_airport_pool(tmp_path, monkeypatch):
    """``n_airports`` reaches the generator for both splits (validation from another seed) and names the dataset."""
    import vbl_robust.detect.train as tr
    scenes = importlib.import_module("vbl_robust.scenes.generate")  # the module: the package's name is the function

    calls = []

    def fake_generate(n, seed=0, **kw):
        calls.append((n, seed, kw.get("n_airports")))
        return _samples(n)

    def stop(tr_samples, va_samples, root, **kw):
        raise RuntimeError(f"built {root.name}")

    monkeypatch.setattr(scenes, "generate", fake_generate)
    monkeypatch.setattr(tr, "build_dataset", stop)
    with pytest.raises(RuntimeError, match="built dataset_32px_1crops_box2_ap57$"):
        train(tmp_path, n_train=4, n_val=2, imgsz=32, crops_per_sample=1, min_box=2, n_airports=57)
    assert calls == [(4, 0, 57), (2, tr.VAL_SEED_OFFSET, 57)]


class _ShiftedTruth:
    """Fake detector: the true corners of the sample in the batch, shifted by a constant."""

    input_size = None

    def __init__(self, samples, shift):
        self.samples, self.shift, self.i = samples, np.asarray(shift), 0

    def detect(self, context):
        from vbl_robust.detect.base import Detections

        out = []
        for _ in range(len(context)):
            s = self.samples[self.i]
            self.i += 1
            out.append(Detections(np.zeros((1, 4)), np.array([0.9]), (s.corners_2d + self.shift)[None]))
        return out


def test_evaluate_scores_known_errors():
    from vbl_robust.detect.evaluate import comparison_key, evaluate_detector, range_rows
    from vbl_robust.geometry.camera import project, rot_y, runway_corners

    samples = []
    for i, (d, env) in enumerate([(1500.0, "close"), (3000.0, "medium"), (5000.0, "far")]):
        K = intrinsics(512, 512)
        R = rot_y(3.0)  # looking along the runway, 3° down
        C = np.array([-d, 0.0, d * np.tan(np.radians(3.0))])
        z = runway_corners(3000.0, 45.0)
        samples.append(Sample(id=str(i), K=K, corners_3d=z, corners_2d=project(z, R, C, K), position=C, width=512,
                              height=512, _image=np.zeros((512, 512, 3), np.uint8), meta={"envelope": env}))
    r = evaluate_detector(_ShiftedTruth(samples, [0.25, -0.5]), samples, batch=2)
    assert r.detected.all()
    assert np.allclose(r.corner_err, np.hypot(0.25, 0.5) * 2)  # 1024-px units: twice the 512-px error
    rows = range_rows(r)
    assert [row["envelope"] for row in rows] == ["far", "medium", "close", "all"]
    assert rows[-1]["bias_u_px"] == pytest.approx(0.5) and rows[-1]["bias_v_px"] == pytest.approx(-1.0)
    assert np.all(r.pos_err_m["ippe_lm"] > 0) and np.all(np.isfinite(r.pos_err_m["ippe_lm"]))
    assert r.correct.all() and rows[-1]["correct_rate"] == 1.0  # 1.1 px ≪ a quarter of each runway's box
    # a 40-px miss is a detection but not a correct one for the small (far, medium) runways
    off = evaluate_detector(_ShiftedTruth(samples, [20.0, 0.0]), samples, pnp_methods=())
    assert off.detected.all()
    assert off.correct.tolist() == list(off.box_diag * 0.25 >= 40.0) and not off.correct.all()
    exact = evaluate_detector(_ShiftedTruth(samples, [0.0, 0.0]), samples)
    assert np.all(exact.pos_err_m["ippe_lm"] < 1e-3)
    assert comparison_key(exact) >= comparison_key(r)


def test_new_stage_starts_from_previous_weights(tmp_path):
    """With a zero learning rate, a new stage's conv weights equal the previous stage's (not a fresh init)."""
    import torch

    frozen = dict(optimizer="SGD", lr0=0.0, lrf=1.0, momentum=0.0, weight_decay=0.0, warmup_epochs=0.0,
                  warmup_bias_lr=0.0)
    kw = dict(samples=_samples(6), n_val=2, imgsz=64, epochs=1, batch=4, workers=0, seed=0)
    r0 = train(tmp_path / "run", **kw)
    r1 = train(tmp_path / "run", resume=True, trust_checkpoints=True, **kw, **frozen)

    def conv_weights(p):
        m = torch.load(p, weights_only=False)["ema"] or torch.load(p, weights_only=False)["model"]
        return [w.float() for n, w in m.state_dict().items() if n.endswith("conv.weight")]

    a, b = conv_weights(r0.best), conv_weights(r1.best)
    assert len(a) == len(b) > 10
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


class _Levelled(_ShiftedTruth):
    """Fake detector: true corners with each threshold edge turned level about its midpoint (a roll-blind model)."""

    def detect(self, context):
        from vbl_robust.detect.base import Detections

        out = []
        for _ in range(len(context)):
            c = self.samples[self.i].corners_2d.copy()
            self.i += 1
            for a, b in ((0, 1), (3, 2)):
                mid, half = (c[a] + c[b]) / 2, np.linalg.norm(c[a] - c[b]) / 2
                c[a], c[b] = mid + [half, 0.0], mid - [half, 0.0]
            out.append(Detections(np.zeros((1, 4)), np.array([0.9]), c[None]))
        return out


def test_edge_tilt_slope_tells_a_roll_blind_detector_from_an_exact_one():
    from vbl_robust.detect.evaluate import edge_angles_deg, edge_tilt_slope, evaluate_detector, range_rows
    from vbl_robust.geometry.camera import project, rot_x, rot_y, runway_corners

    samples = []
    z = runway_corners(3000.0, 45.0)
    for i, roll in enumerate([-20.0, -8.0, 0.0, 5.0, 15.0, 25.0]):
        R = rot_y(3.0) @ rot_x(roll)
        C = np.array([-1500.0, 0.0, 1500.0 * np.tan(np.radians(3.0))])
        K = intrinsics(512, 512)
        samples.append(Sample(id=str(i), K=K, corners_3d=z, corners_2d=project(z, R, C, K), position=C, width=512,
                              height=512, _image=np.zeros((512, 512, 3), np.uint8), meta={"envelope": "close"}))
    true_angles = edge_angles_deg(np.array([s.corners_2d for s in samples]))
    assert np.ptp(true_angles) > 20.0  # the roll really tilts the edges
    exact = evaluate_detector(_ShiftedTruth(samples, [0.0, 0.0]), samples, pnp_methods=())
    level = evaluate_detector(_Levelled(samples, [0.0, 0.0]), samples, pnp_methods=())
    assert edge_tilt_slope(exact) == pytest.approx(1.0)
    assert abs(edge_tilt_slope(level)) < 1e-6
    assert range_rows(level)[-1]["edge_tilt_slope"] == pytest.approx(edge_tilt_slope(level))
    assert np.isnan(edge_tilt_slope(exact, np.zeros(len(samples), bool)))  # nothing to fit


def test_crop_window_reaches_the_dataset_and_names_it(tmp_path, monkeypatch):
    """A non-default ``crop_jitter`` is the build's jitter and tags the directory; the default one changes nothing."""
    import vbl_robust.detect.train as tr

    seen = []

    def stop(tr_samples, va_samples, root, **kw):
        seen.append((root.name, kw.get("jitter")))
        raise RuntimeError("stop")

    monkeypatch.setattr(tr, "build_dataset", stop)
    for jitter in (None, {"min_side": 64.0}, {"min_side": 40.0}):
        with pytest.raises(RuntimeError, match="stop"):
            train(tmp_path / "run", samples=_samples(6), imgsz=32, crops_per_sample=1, min_box=2, crop_jitter=jitter)
    (n0, j0), (n1, j1), (n2, j2) = seen
    assert n0 == n1 == "dataset_32px_1crops_box2" and j0 is None and j1 is None
    assert n2.startswith("dataset_32px_1crops_box2_crop") and j2 == tr.CropJitter(min_side=40.0)


def test_crops_only_training_lists_only_the_crop_views(tmp_path, monkeypatch):
    """``full_views=False`` trains a pass-2 network on the crops alone (the same rendered dataset; validation keeps
    its full views); ``crops_used`` still picks the first crops; the default trains on every view."""
    from pathlib import Path

    import ultralytics
    import yaml

    seen = []

    class FakeYOLO:
        def __init__(self, weights):
            pass

        def train(self, **kw):
            seen.append(Path(kw["data"]))

    monkeypatch.setattr(ultralytics, "YOLO", FakeYOLO)
    common = dict(samples=_samples(6), n_val=2, imgsz=32, crops_per_sample=2, min_box=2, epochs=1, workers=0)
    for run, kw in (("a", dict(full_views=False)), ("b", dict(full_views=False, crops_used=1)),
                    ("c", dict(crops_used=1)), ("d", {})):
        train(tmp_path / run, **common, **kw)

    def views(data: Path, split: str) -> list[str]:
        """View indices (file stem suffix) of one split of a data YAML, sorted."""
        src = data.parent / yaml.safe_load(data.read_text())[split]
        names = src.glob("*.png") if src.is_dir() else map(Path, src.read_text().split())
        return sorted(p.stem.rsplit("_", 1)[1] for p in names)

    n = len(list(seen[0].parent.glob("images/train/*_0.png")))  # training samples
    assert n >= 4
    assert [views(d, "train") for d in seen] == [sorted(["1", "2"] * n), ["1"] * n, sorted(["0", "1"] * n),
                                                 sorted(["0", "1", "2"] * n)]
    assert "0" in views(seen[0], "val")
    for bad in (dict(detector="single"), dict(crops_used=0)):
        with pytest.raises(ValueError, match="crops only"):
            train(tmp_path / "e", **{**common, "full_views": False, **bad})


def test_ship_validates_the_checkpoint_before_writing_anything(tmp_path):
    """Issue 48 item 4: a file that is no pose checkpoint (or a bad version) ships nothing: the installed weights and
    default.json stay as they were."""
    from vbl_robust.detect.shipped import DEFAULT_MODEL
    from vbl_robust.detect.train import ship

    models = tmp_path / "models"
    models.mkdir()
    (models / "default.json").write_text('{"version": 9}')
    (models / DEFAULT_MODEL.name).write_bytes(b"installed")
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="nothing shipped"):
        ship(garbage, detector="twostage", imgsz=320, info={"version": 99}, models_dir=models)
    with pytest.raises(ValueError, match="version must be an integer >= 1"):
        ship(DEFAULT_MODEL, detector="twostage", imgsz=320, info={"version": "99"}, models_dir=models)
    assert (models / "default.json").read_text() == '{"version": 9}'
    assert (models / DEFAULT_MODEL.name).read_bytes() == b"installed"
    assert sorted(p.name for p in models.iterdir()) == ["default.json", DEFAULT_MODEL.name]
    # the shipped model itself ships (a pose model with 4 corners)
    out = ship(DEFAULT_MODEL, detector="twostage", imgsz=320, info={"version": 10}, models_dir=models)
    assert out.stat().st_size > 1000 and '"version": 10' in (models / "default.json").read_text()


def test_a_first_stage_can_be_yolo26_pose_and_runs_in_the_pipeline(tmp_path):
    """Issue 49: YOLO26-pose (residual log-likelihood keypoints) built offline from its .yaml, trained on the
    corners, loaded as a detector and evaluated by the pipeline (4 corners per row; one tiny epoch: no accuracy)."""
    import numpy as np

    from vbl_robust.detect.ultralytics import UltralyticsDetector
    from vbl_robust.pipeline import Objective
    from vbl_robust.space import ParameterBox

    with pytest.raises(ValueError, match="architecture must be one of yolov8n-pose, yolo26n-pose"):
        train(tmp_path / "bad", samples=_samples(8), architecture="yolo99-pose")
    samples = _samples(8)
    r = train(tmp_path / "run", samples=samples, n_val=2, imgsz=64, epochs=1, batch=4, workers=0, seed=0,
              architecture="yolo26n-pose")
    det = UltralyticsDetector(r.best, trust=True, imgsz=64)
    head = det.model.head  # the σ head is kept (detect.ultralytics.PoseWithSigma)
    assert type(head).__name__ == "Pose26" and list(head.kpt_shape) == [4, 3] and det.gives_sigma
    rec = Objective(samples[0], det, ParameterBox({"roll_deg": (-5.0, 5.0)})).evaluate(np.array([[0.0], [2.0]]))
    assert np.asarray(rec.keypoints).shape == (2, 4, 2) and len(rec.reason) == 2
    dets = det.detect(Objective(samples[0], det, ParameterBox({"roll_deg": (-5.0, 5.0)})).context(np.zeros((1, 1))))
    assert dets[0].keypoint_sigma is not None and (dets[0].keypoint_sigma > 0).all()
