"""An ONNX model that could only fail every evaluation is refused when it is loaded, in one line naming the file,
the key or the shape: unreadable or impossible pose metadata, an output of another layout (declared, or found by
one forward pass where the graph leaves the channels symbolic)."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from vbl_robust.detect.onnx import OnnxDetector, check_output_shape, pose_metadata

META = {"kpt_shape": "[4, 3]", "names": "{0: 'runway'}", "imgsz": "[64, 64]"}


def _model(path, channels: int, *, meta=None, declared=None, rank3: bool = True):
    """A 64-px pose-like graph: Conv(3 → channels, 8 × 8, stride 8) then (B, channels, 64) — the layout of an
    ultralytics pose export when ``channels`` = 4 + 1 + 12."""
    w = numpy_helper.from_array(np.full((channels, 3, 8, 8), 0.01, np.float32), "W")
    shape = numpy_helper.from_array(np.array([0, channels, -1] if rank3 else [0, -1], np.int64), "S")
    nodes = [helper.make_node("Conv", ["images", "W"], ["c"], kernel_shape=[8, 8], strides=[8, 8]),
             helper.make_node("Reshape", ["c", "S"], ["output0"])]
    x = helper.make_tensor_value_info("images", TensorProto.FLOAT, ["batch", 3, 64, 64])
    out = declared if declared is not None else (["batch", channels, 64] if rank3 else ["batch", channels * 64])
    y = helper.make_tensor_value_info("output0", TensorProto.FLOAT, out)
    model = helper.make_model(helper.make_graph(nodes, "g", [x], [y], [w, shape]),
                              opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    for key, value in (META if meta is None else meta).items():
        model.metadata_props.add(key=key, value=value)
    onnx.save(model, path)
    return path


def test_a_pose_layout_loads_and_says_whether_it_gives_sigma(tmp_path):
    assert OnnxDetector(_model(tmp_path / "plain.onnx", 17)).gives_sigma is False
    assert OnnxDetector(_model(tmp_path / "sigma.onnx", 25)).gives_sigma is True
    # channels left symbolic in the graph: one forward pass tells the layout
    assert OnnxDetector(_model(tmp_path / "sym.onnx", 17, declared=["b", "c", "a"])).gives_sigma is False


@pytest.mark.parametrize("key, value, message", [
    ("kpt_shape", "[4, 3", "kpt_shape = '[4, 3' is not readable"),
    ("kpt_shape", "4", "kpt_shape = '4': expected [keypoints, values per keypoint]"),
    ("kpt_shape", "[4, 3, 1]", "expected [keypoints, values per keypoint]"),
    ("kpt_shape", "[17, 3]", "pose model has 17 keypoints; runway corners need 4"),
    ("kpt_shape", "[4, 2]", "2 values per keypoint"),
    ("kpt_shape", "__import__('os').system('echo hi')", "is not readable"),
    ("names", "{0: 'runway'", "names = \"{0: 'runway'\" is not readable"),
    ("names", "3", "expected the class names"),
    ("imgsz", "-64", "imgsz = '-64': expected a side in pixels"),
    ("imgsz", "[64, 'x']", "expected a side in pixels"),
])
def test_impossible_metadata_is_refused_in_one_line(tmp_path, key, value, message):
    path = _model(tmp_path / "m.onnx", 17, meta={**META, key: value})
    with pytest.raises(ValueError, match="^" + str(path).replace(".", r"\.")) as exc:
        OnnxDetector(path)
    assert message in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(ValueError):
        pose_metadata(path, {**META, key: value})


@pytest.mark.parametrize("channels, declared, rank3, message", [
    (5, None, True, "5 channels, expected (batch, 17 or 25 channels"),
    (5, ["b", "c", "a"], True, "5 channels, expected"),  # found by the forward pass
    (17, None, False, "expected (batch, 17 or 25 channels"),
])
def test_an_output_of_another_layout_is_refused_at_load(tmp_path, channels, declared, rank3, message):
    path = _model(tmp_path / "m.onnx", channels, declared=declared, rank3=rank3)
    with pytest.raises(ValueError, match="output shape") as exc:
        OnnxDetector(path)
    assert message in str(exc.value) and str(path) in str(exc.value)


def test_the_layout_check_itself():
    assert check_output_shape("m", ["b", 17, "a"], 1) is False
    assert check_output_shape("m", [1, 26, 8400], 2) is True
    with pytest.raises(ValueError, match="end-to-end"):
        check_output_shape("m", [1, 300, 18], 1)
    with pytest.raises(ValueError, match="no anchors"):
        check_output_shape("m", [1, 17, 0], 1)


def test_the_command_refuses_such_a_model_before_anything_is_stored(tmp_path):
    from typer.testing import CliRunner

    from vbl_robust.cli import app

    path = _model(tmp_path / "m.onnx", 17, meta={**META, "kpt_shape": "[4, 3"})
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["audit", "--model", str(path), "--n", "1", "--width", "96", "--height", "96",
                                   "--methods", "random", "--max-evals", "2", "--no-landscape", "--workers", "1",
                                   "--out", str(out)])
    assert res.exit_code == 2 and "kpt_shape = '[4, 3' is not readable" in res.output, res.output
    assert "Traceback" not in res.output and not out.exists()
