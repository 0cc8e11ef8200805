"""The shipped model is used by default only once it is validated (``validated`` in its default.json);
its open goals travel with every run."""

import json

from vbl_robust.detect import shipped
from vbl_robust.detect.shipped import DetectorSpec, default_model_caveats, default_model_status


def _fake_model(tmp_path, monkeypatch, info):
    weights = tmp_path / "runway_yolov8n_pose.pt"
    weights.write_bytes(b"x")
    if info is not None:
        (tmp_path / "default.json").write_text(json.dumps(info))
    monkeypatch.setattr(shipped, "MODELS_DIR", tmp_path)
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", weights)


def test_unvalidated_shipped_model_falls_back_to_the_oracle(tmp_path, monkeypatch):
    _fake_model(tmp_path, monkeypatch, {"detector": "twostage", "imgsz": 320})
    assert "does not meet its validation gates" in default_model_status()
    spec = DetectorSpec.auto(oracle_noise_px=1.0)
    assert spec.kind == "oracle" and spec.options == {"noise_px": 1.0}
    spec, why = DetectorSpec.choose(oracle_noise_px=1.0)  # what the CLI prints
    assert spec.kind == "oracle" and "does not meet its validation gates" in why


def test_validated_shipped_model_is_the_default(tmp_path, monkeypatch):
    _fake_model(tmp_path, monkeypatch, {"detector": "twostage", "imgsz": 320, "validated": True})
    assert default_model_status() == ""
    assert DetectorSpec.auto().kind == "default"
    assert default_model_caveats() == []


def test_meeting_every_goal_is_not_required_but_open_goals_are_recorded(tmp_path, monkeypatch):
    goal = "median position error 6.9 % of slant (goal 5 %)"
    _fake_model(tmp_path, monkeypatch, {"detector": "twostage", "imgsz": 320, "version": 7, "validated": True,
                                        "open_goals": [goal]})
    spec = DetectorSpec.auto()
    assert spec.kind == "default" and default_model_caveats() == [goal]
    ident = spec.identity()
    assert ident["open_goals"] == [goal] and ident["name"].endswith("v7")


def test_a_validation_flag_that_is_not_true_keeps_the_oracle(tmp_path, monkeypatch):
    _fake_model(tmp_path, monkeypatch, {"detector": "twostage", "imgsz": 320, "validated": "yes"})
    assert DetectorSpec.auto().kind == "oracle"


def test_missing_model_is_named(tmp_path, monkeypatch):
    monkeypatch.setattr(shipped, "DEFAULT_MODEL", tmp_path / "absent.pt")
    assert "not installed" in default_model_status()
    assert DetectorSpec.auto().kind == "oracle"
