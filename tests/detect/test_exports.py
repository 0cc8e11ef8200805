import importlib

import vbl_robust as vr
import vbl_robust.detect as detect


def test_adapters_are_exported_lazily_and_consistently():
    assert vr.UltralyticsDetector is importlib.import_module("vbl_robust.detect.ultralytics").UltralyticsDetector
    assert vr.OnnxDetector is importlib.import_module("vbl_robust.detect.onnx").OnnxDetector
    assert vr.default_detector is importlib.import_module("vbl_robust.detect.shipped").default_detector
    assert importlib.import_module("vbl_robust.detect.twostage").TwoStageDetector.__name__ == "TwoStageDetector"
    for face in (vr, detect):
        try:
            face.NotADetector  # noqa: B018
        except AttributeError as exc:
            assert "NotADetector" in str(exc)
        else:
            raise AssertionError("unknown names must raise AttributeError")
