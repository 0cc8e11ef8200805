import vbl_robust as vr
import vbl_robust.detect as detect


def test_adapters_are_exported_lazily_and_consistently():
    assert detect.UltralyticsDetector is vr.UltralyticsDetector
    assert detect.OnnxDetector is vr.OnnxDetector
    assert detect.default_detector is vr.default_detector
    assert detect.TwoStageDetector.__name__ == "TwoStageDetector"
    try:
        detect.NotADetector  # noqa: B018
    except AttributeError as exc:
        assert "NotADetector" in str(exc)
    else:
        raise AssertionError("unknown names must raise AttributeError")
