"""``DetectorSpec.from_choice``: the one way a command or a workflow makes a detector from the user's choice (model
name or path, oracle, noise, design, engine, device, trust), refusing a bad choice in one line."""

import json

import pytest

from vbl_robust.consent import refuse_untrusted
from vbl_robust.detect import shipped
from vbl_robust.detect.engines import resolve_engine
from vbl_robust.detect.shipped import DetectorSpec


@pytest.fixture()
def pt(tmp_path):
    path = tmp_path / "mine.pt"
    path.write_bytes(b"x")
    return path


def test_the_oracle_with_its_noise():
    assert DetectorSpec.from_choice(oracle=True) == DetectorSpec.oracle()
    assert DetectorSpec.from_choice(oracle=True, oracle_noise=1.5).options == {"noise_px": 1.5}


@pytest.mark.parametrize("choice, message", [
    ({"design": "triple"}, "--detector triple: choose auto, single or twostage"),
    ({"oracle": True, "design": "single"}, "--detector applies to a model, not to --oracle"),
    ({"oracle": True, "engine": "openvino"}, "--engine openvino applies to a model, not to --oracle"),
    ({"oracle": True, "device": "tpu"}, "--device tpu applies to a model, not to --oracle (the oracle needs no device)"),
    ({"oracle_noise": 2.0}, "--oracle-noise 2 applies to --oracle only"),
    ({"oracle": True, "model": "default"}, "--oracle and --model are exclusive"),
    ({"device": "tpu"}, "--device tpu: device: expected auto, cpu, cuda or cuda:N, got 'tpu'"),
    ({"engine": "tensorrt"}, "--engine tensorrt: engine must be auto or one of"),
    ({"model": "weights.h5"}, "--model weights.h5: expected a .pt (ultralytics) or .onnx file"),
])
def test_a_bad_choice_is_one_line(choice, message):
    with pytest.raises(ValueError) as info:
        DetectorSpec.from_choice(**choice)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


def test_a_pickle_loads_only_with_trust_and_the_message_names_the_option(pt, tmp_path):
    with pytest.raises(ValueError, match=r"--model .*mine.pt: a .pt file is a pickle that runs code when loaded; "
                                         "pass --trust-model if you trust it"):
        DetectorSpec.from_choice(pt)
    with pytest.raises(ValueError, match=r"^--init .*mine.pt: a .pt file is a pickle"):
        DetectorSpec.from_choice(pt, option="--init")
    with pytest.raises(FileNotFoundError, match="missing.pt: model file not found"):
        DetectorSpec.from_choice(tmp_path / "missing.pt", trust=True)
    spec = DetectorSpec.from_choice(pt, trust=True, design="twostage", options={"imgsz": 96})
    assert spec.kind == "ultralytics" and spec.trust and spec.options == {"design": "twostage", "imgsz": 96}
    assert DetectorSpec.from_choice(pt, trust=True) == DetectorSpec.from_path(pt, trust=True)
    onnx = tmp_path / "mine.onnx"
    onnx.write_bytes(b"x")
    assert DetectorSpec.from_choice(onnx).kind == "onnx"  # no pickle: no trust needed


def test_refuse_untrusted_is_the_one_refusal():
    refuse_untrusted("x.pt", True)
    with pytest.raises(ValueError, match="^x.pt: a .pt file is a pickle"):
        refuse_untrusted("x.pt", False)


def test_engine_and_device_are_resolved_and_kept_only_where_not_the_defaults():
    assert DetectorSpec.from_choice("default", engine="torch", device="cpu") == DetectorSpec.shipped("default")
    spec = DetectorSpec.from_choice("default", design="single", engine="auto")
    engine = resolve_engine("auto", "cpu")
    assert spec.options == {"design": "single", **({} if engine == "torch" else {"engine": engine})}


def _fake_models(tmp_path, monkeypatch, info, hardened=False):
    weights = tmp_path / "runway_yolov8n_pose.pt"
    weights.write_bytes(b"x")
    (tmp_path / "default.json").write_text(json.dumps(info))
    if hardened:
        (tmp_path / "hardened").mkdir()
        (tmp_path / "hardened" / weights.name).write_bytes(b"y")
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path)
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", weights)


def test_shipped_models_by_name(tmp_path, monkeypatch):
    _fake_models(tmp_path, monkeypatch, {"detector": "twostage", "validated": True})
    with pytest.raises(ValueError, match="^--model hardened: the shipped hardened detector model is not installed"):
        DetectorSpec.from_choice("hardened")
    _fake_models(tmp_path, monkeypatch, {"detector": "twostage", "validated": True}, hardened=True)
    spec = DetectorSpec.from_choice("hardened", design="single")
    assert spec.shipped_name == "hardened" and spec.options == {"design": "single", "model": "hardened"}
    assert spec.model_file == tmp_path / "hardened" / "runway_yolov8n_pose.pt"
    assert DetectorSpec.from_choice().kind == "default"  # validated: the shipped model by default


def test_no_model_falls_back_to_the_oracle_with_its_noise(tmp_path, monkeypatch):
    _fake_models(tmp_path, monkeypatch, {"detector": "twostage"})  # not validated
    assert DetectorSpec.from_choice() == DetectorSpec.oracle()
    spec = DetectorSpec.from_choice(oracle_noise=1.0, noise_needs_oracle=False)  # the demo's stand-in
    assert spec == DetectorSpec.oracle(1.0)


def test_the_hardening_rounds_build_their_detector_from_a_choice(tiny_pose_pt):
    from vbl_robust.detect.twostage import TwoStageDetector

    det = DetectorSpec.from_choice(tiny_pose_pt, design="twostage", trust=True, options={"imgsz": 96}).build()
    assert isinstance(det, TwoStageDetector) and det.first.imgsz == 96
