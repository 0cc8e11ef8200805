"""UltralyticsDetector: loading checks, black-box vs differentiable paths, agreement with YOLO.predict()."""

from __future__ import annotations

import pytest
import torch
from detect_helpers import runway_image

from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector


@pytest.fixture(scope="module")
def det(tiny_pose_pt):
    return UltralyticsDetector(tiny_pose_pt, trust=True)


def test_untrusted_pickle_is_refused(tiny_pose_pt):
    with pytest.raises(ValueError, match="--trust-model"):
        UltralyticsDetector(tiny_pose_pt)


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pt"):
        UltralyticsDetector(tmp_path / "nope.pt", trust=True)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"this is not a checkpoint")
    with pytest.raises(ValueError, match="not a loadable"):
        UltralyticsDetector(bad, trust=True)
    junk = tmp_path / "junk.pt"
    torch.save({"something": 1}, junk)
    with pytest.raises(ValueError, match="not an ultralytics model"):
        UltralyticsDetector(junk, trust=True)


def test_wrong_keypoint_count(make_pose_ckpt):
    p = make_pose_ckpt("kp17.pt", nk=17)
    with pytest.raises(ValueError, match="17 keypoints"):
        UltralyticsDetector(p, trust=True)


def test_not_a_pose_model(tmp_path):
    from vbl_robust.detect.offline import import_ultralytics

    import_ultralytics()
    from ultralytics.nn.tasks import DetectionModel

    p = tmp_path / "det.pt"
    torch.save({"model": DetectionModel("yolov8n.yaml", nc=1, verbose=False)}, p)
    with pytest.raises(ValueError, match="not a pose model"):
        UltralyticsDetector(p, trust=True)


def test_end_to_end_head_rejected(tiny_pose_pt, tmp_path):
    ck = torch.load(tiny_pose_pt, weights_only=False)
    head = ck["model"].model[-1]
    head.one2one_cv2 = head.cv2  # makes the head report end2end
    head._end2end = True
    p = tmp_path / "e2e.pt"
    torch.save(ck, p)
    with pytest.raises(ValueError, match="end-to-end"):
        UltralyticsDetector(p, trust=True)


def test_onnx_path_points_to_onnx_detector(tmp_path):
    p = tmp_path / "m.onnx"
    p.write_bytes(b"x")
    with pytest.raises(ValueError, match="OnnxDetector"):
        UltralyticsDetector(p, trust=True)


def test_paths_agree_and_match_predict(det, tiny_pose_pt):
    from ultralytics import YOLO

    img, _ = runway_image(64)
    d = det.detect(img)[0]
    t = det.top(img)
    assert torch.equal(torch.as_tensor(d.keypoints[0]).float(), t.keypoints[0]) and float(d.conf[0]) == float(t.conf[0])
    r = YOLO(str(tiny_pose_pt)).predict(img[:, :, ::-1].copy(), imgsz=64, conf=1e-9, verbose=False)[0]
    # predict(): ultralytics edge coordinates (ours + 0.5), clipped to the image
    ours = (t.keypoints[0] + 0.5).clamp(0, 64)
    assert float(r.boxes.conf[0]) == pytest.approx(float(t.conf[0]), abs=1e-6)
    assert torch.allclose(r.keypoints.xy[0], ours, atol=1e-3)
    assert ((t.keypoints[0] + 0.5 > 0) & (t.keypoints[0] + 0.5 < 64)).all()  # the comparison is not all clipping


def test_protocol_and_selection_agree(det):
    from vbl_robust.detect.base import DifferentiableDetector, select

    assert isinstance(det, DifferentiableDetector) and det.input_size == 64
    imgs = torch.stack([torch.as_tensor(runway_image(64, seed=s)[0]) for s in range(3)])
    x = imgs.permute(0, 3, 1, 2).float() / 255
    sel = select(det.detect(x), conf_threshold=0.0)
    conf, kp = det.detect_top(x)
    assert torch.allclose(torch.as_tensor(sel.keypoints).float(), kp, atol=1e-5)
    assert torch.allclose(torch.as_tensor(sel.conf).float(), conf, atol=1e-7)


def test_batch_equals_single_and_chunking(det):
    imgs = torch.stack([torch.as_tensor(runway_image(64, seed=s)[0]) for s in range(5)])
    det.chunk = 2
    t = det.top(imgs)
    det.chunk = 16
    for b in range(5):
        tb = det.top(imgs[b].numpy())
        assert torch.allclose(tb.keypoints[0], t.keypoints[b], atol=1e-4)


def test_letterbox_maps_back_to_image_pixels(det):
    """A non-square image: detection on it equals detection on its explicit 114-padded square version."""
    img, _ = runway_image(64)
    crop = img[8:56]  # 48 x 64
    padded = img.copy()
    padded[:8] = 114
    padded[56:] = 114
    a = det.top(crop).keypoints[0]
    b = det.top(padded).keypoints[0]
    assert torch.allclose(a + torch.tensor([0.0, 8.0]), b, atol=1e-3)


def test_gradients_reach_the_image(det):
    img, _ = runway_image(64)
    x = torch.as_tensor(img).permute(2, 0, 1)[None].float().div(255).requires_grad_(True)
    t = det.top(x)
    (t.keypoints.sum() + t.conf.sum()).backward()
    assert x.grad is not None and torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_two_stage_paths_agree_and_differentiate(det):
    two = TwoStageDetector(det, min_side=32)
    img, _ = runway_image(128)
    x = torch.as_tensor(img).permute(2, 0, 1)[None].float().div(255).requires_grad_(True)
    t = two.top(x)
    d = two.detect(img)[0]
    assert torch.allclose(torch.as_tensor(d.keypoints[0]).float(), t.keypoints[0].detach(), atol=1e-5)
    t.keypoints.sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_ship_and_default_detector(tiny_pose_pt, tmp_path, monkeypatch):
    import vbl_robust.detect.shipped as shipped
    from vbl_robust.detect.train import ship

    out = ship(tiny_pose_pt, detector="twostage", imgsz=64, models_dir=tmp_path, info={"note": "test"})
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path.resolve())
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", out)
    d = shipped.default_detector()  # the shipped model: no trust flag needed
    assert isinstance(d, TwoStageDetector) and d.imgsz == 64 and d.input_size is None
    img, _ = runway_image(64)
    assert len(d.detect(torch.as_tensor(img).permute(2, 0, 1)[None] / 255.0)[0]) == 1
    with pytest.raises(ValueError, match="twostage"):
        ship(tiny_pose_pt, detector="double", imgsz=64, models_dir=tmp_path)


def test_shipped_crop_window_follows_the_training_crops(tiny_pose_pt, tmp_path, monkeypatch):
    """Weights trained on magnified crops ship with their window; a user's model takes it as options."""
    import vbl_robust.detect.shipped as shipped
    from vbl_robust.detect.train import CropJitter, ship

    out = ship(tiny_pose_pt, detector="twostage", imgsz=64, models_dir=tmp_path,
               crop_jitter=CropJitter(min_side=40.0))
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path.resolve())
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", out)
    assert shipped.default_model_info()["twostage"] == {"margin": 1.5, "min_side": 40.0}
    d = shipped.default_detector()
    assert isinstance(d, TwoStageDetector) and (d.min_side, d.margin) == (40.0, 1.5)
    assert not isinstance(shipped.default_detector(design="single"), TwoStageDetector)
    # the default window writes no "twostage" entry: older default.json files read the same
    ship(tiny_pose_pt, detector="twostage", imgsz=64, models_dir=tmp_path, crop_jitter=CropJitter())
    assert "twostage" not in shipped.default_model_info() and shipped.default_detector().min_side == 64.0
    spec = shipped.DetectorSpec("ultralytics", str(tiny_pose_pt), trust=True,
                                options={"design": "twostage", "min_side": 48})
    assert spec.build().min_side == 48.0
    with pytest.raises(ValueError, match="twostage"):
        shipped.DetectorSpec("ultralytics", str(tiny_pose_pt), trust=True, options={"min_side": 48}).build()
    with pytest.raises(ValueError, match="needs detector='twostage'"):
        ship(tiny_pose_pt, detector="single", imgsz=64, models_dir=tmp_path, crop_jitter=CropJitter(min_side=40.0))


@pytest.mark.skipif(not __import__("vbl_robust.detect.shipped", fromlist=["x"]).DEFAULT_MODEL.exists(),
                    reason="no shipped model")
def test_shipped_model_loads_and_runs():
    from vbl_robust.detect.base import DifferentiableDetector
    from vbl_robust.detect.shipped import default_detector

    d = default_detector()
    assert isinstance(d, DifferentiableDetector)
    x = torch.rand(2, 3, 256, 256)
    conf, kp = d.detect_top(x)
    assert conf.shape == (2,) and kp.shape == (2, 4, 2) and torch.isfinite(kp).all()


def test_the_hardened_model_ships_beside_the_default(tiny_pose_pt, tmp_path, monkeypatch):
    """``ship --as hardened`` / ``--model hardened``: a second shipped model in its own directory; the default's
    spec, key and files stay as they were."""
    import vbl_robust.detect.shipped as shipped
    from vbl_robust.detect.shipped import DetectorSpec, default_model_status
    from vbl_robust.detect.train import ship

    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path)
    default = ship(tiny_pose_pt, detector="twostage", imgsz=64, models_dir=tmp_path, info={"validated": True})
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", default)
    before, default_bytes = DetectorSpec("default").key(), default.read_bytes()
    spec = DetectorSpec.shipped("hardened")
    assert spec.model_file is None and "it comes from vbl-robust harden" in default_model_status("hardened")
    with pytest.raises(FileNotFoundError, match="hardened detector model is not installed"):
        spec.build()
    hard = ship(tiny_pose_pt, detector="twostage", imgsz=64, models_dir=shipped.shipped_model_dir("hardened"),
                info={"validated": True, "version": 1, "open_goals": ["a goal"]})
    assert hard == tmp_path / "hardened" / default.name and default.read_bytes() == default_bytes
    ident = spec.identity()
    assert spec.model_file == hard and ident["name"] == "shipped hardened model (runway_yolov8n_pose.pt) v1"
    assert ident["open_goals"] == ["a goal"] and ident["options"] == {"model": "hardened"}
    assert spec.key() != before and DetectorSpec("default").key() == before
    assert DetectorSpec.shipped("default") == DetectorSpec("default")
    img, _ = runway_image(64)
    assert len(spec.build().detect(torch.as_tensor(img).permute(2, 0, 1)[None] / 255.0)[0]) == 1
    with pytest.raises(ValueError, match="shipped models: default, hardened"):
        DetectorSpec.shipped("robust")


def test_the_commands_name_a_missing_hardened_model_in_one_line(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from vbl_robust.cli import app
    from vbl_robust.detect import shipped

    # an installation without the hardened model (the repository ships one since issue 29)
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path / "installed_models")
    out = tmp_path / "out"
    out.mkdir()
    runner = CliRunner()
    for args, message in ((["audit", "--model", "hardened", "--out", str(out / "a")],
                           "--model hardened: the shipped hardened detector model is not installed"),
                          (["harden", "--perturb", "roll_deg", "--model", "hardened", "--out", str(out / "h")],
                           "--model hardened: the shipped hardened detector model is not installed"),
                          (["ship", str(out / "c.pt"), "--version", "1", "--epochs", "1", "--protocol",
                            str(out / "p.json"), "--as", "robust"], "--as robust: shipped models are")):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and message in res.output, (args, res.output)
    assert not any(out.iterdir())
