"""OnnxDetector: export, agreement with the .pt path, bad files."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from detect_helpers import runway_image

from vbl_robust.detect.onnx import OnnxDetector, export_onnx
from vbl_robust.detect.ultralytics import UltralyticsDetector


@pytest.fixture(scope="module")
def onnx_path(tiny_pose_pt, tmp_path_factory):
    return export_onnx(tiny_pose_pt, tmp_path_factory.mktemp("onnx") / "tiny.onnx", trust=True)


def test_export_requires_trust(tiny_pose_pt, tmp_path):
    with pytest.raises(ValueError, match="trust"):
        export_onnx(tiny_pose_pt, tmp_path / "x.onnx")


def test_onnx_matches_pt(onnx_path, tiny_pose_pt):
    pt = UltralyticsDetector(tiny_pose_pt, trust=True)
    ox = OnnxDetector(onnx_path)
    assert ox.imgsz == pt.imgsz == 64
    imgs = torch.stack([torch.as_tensor(runway_image(64, seed=s)[0]) for s in range(3)]).numpy()
    a, b = pt.detect(imgs), ox.detect(imgs)  # batch of 3 through the dynamic axis
    for da, db in zip(a, b, strict=True):
        assert np.allclose(da.keypoints[0], db.keypoints[0], atol=1e-3)
        assert float(da.conf[0]) == pytest.approx(float(db.conf[0]), abs=1e-4)
    ta = pt.top(imgs)
    tb = ox.top(imgs)
    assert torch.allclose(ta.keypoints, tb.keypoints, atol=1e-3)


def test_bad_onnx_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.onnx: ONNX file not found"):
        OnnxDetector(tmp_path / "missing.onnx")
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"garbage")
    with pytest.raises(ValueError, match="not a loadable ONNX"):
        OnnxDetector(bad)


def test_onnx_without_pose_metadata(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("images", TensorProto.FLOAT, ["b", 3, 64, 64])
    y = helper.make_tensor_value_info("out", TensorProto.FLOAT, ["b", 3, 64, 64])
    g = helper.make_graph([helper.make_node("Identity", ["images"], ["out"])], "g", [x], [y])
    p = tmp_path / "plain.onnx"
    model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, p)
    with pytest.raises(ValueError, match="kpt_shape"):
        OnnxDetector(p)
    from vbl_robust.detect.openvino import OpenVinoDetector

    with pytest.raises(ValueError, match="kpt_shape"):  # the same check on the other engine
        OpenVinoDetector(p)
