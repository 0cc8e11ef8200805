"""Inference engines: the same model on ONNX Runtime and OpenVINO (fp32) agrees with torch within 1e-3 px."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from detect_helpers import runway_image

from vbl_robust.detect.base import DetectContext
from vbl_robust.detect.engines import EnginePose, exported_onnx, resolve_engine, with_engine
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    import os

    d = tmp_path_factory.mktemp("engine_cache")
    old = os.environ.get("VBL_ROBUST_CACHE")
    os.environ["VBL_ROBUST_CACHE"] = str(d)
    yield d
    if old is None:
        os.environ.pop("VBL_ROBUST_CACHE")
    else:
        os.environ["VBL_ROBUST_CACHE"] = old


@pytest.fixture(scope="module")
def pt(tiny_pose_pt):
    return UltralyticsDetector(tiny_pose_pt, trust=True)


def _images(n=4, size=64):
    return torch.stack([torch.as_tensor(runway_image(size, seed=s)[0]) for s in range(n)]).permute(0, 3, 1, 2) / 255


def test_export_is_cached_by_the_checkpoint_hash(cache, tiny_pose_pt):
    a = exported_onnx(tiny_pose_pt, trust=True, imgsz=64)
    t = a.stat().st_mtime_ns
    assert exported_onnx(tiny_pose_pt, trust=True, imgsz=64) == a and a.stat().st_mtime_ns == t
    assert a.parent.parent == cache
    with pytest.raises(ValueError, match="trust"):
        exported_onnx(tiny_pose_pt, trust=False, imgsz=96)  # a .pt is a pickle: never unpickled untrusted


def test_processes_needing_one_export_at_once_export_it_once(tmp_path, monkeypatch, tiny_pose_pt):
    """A campaign's workers on a fresh machine all ask for the export at once: one exports, the others wait for
    it and load the whole file (two exports into one temporary file once broke a reproduction run)."""
    import threading
    import time

    import vbl_robust.detect.onnx as onnx_mod

    monkeypatch.setenv("VBL_ROBUST_CACHE", str(tmp_path))
    calls = []

    def slow_export(pt_path, out, *, trust, imgsz):
        calls.append(out)
        time.sleep(0.3)
        out.write_bytes(b"onnx")
        return out

    monkeypatch.setattr(onnx_mod, "export_onnx", slow_export)
    got = []
    threads = [threading.Thread(target=lambda: got.append(exported_onnx(tiny_pose_pt, trust=True, imgsz=64)))
               for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and len(got) == 3 and len(set(got)) == 1 and got[0].read_bytes() == b"onnx"


def test_export_leaves_only_the_model_behind(tmp_path, tiny_pose_pt):
    from vbl_robust.detect.onnx import export_onnx

    export_onnx(tiny_pose_pt, tmp_path / "m.onnx", trust=True)
    assert [p.name for p in tmp_path.iterdir()] == ["m.onnx"]


@pytest.mark.parametrize("engine", ["onnxruntime", "openvino"])
def test_engine_agrees_with_torch_within_1e_3_px(cache, pt, engine):
    fast = with_engine(pt, engine, trust=True)
    assert isinstance(fast, EnginePose) and fast.engine == engine and "32" in fast.precision
    x = DetectContext.of_images(_images())
    a, b = pt.top(x), fast.top(x)
    assert float((a.keypoints - b.keypoints).abs().max()) <= 1e-3
    assert float((a.conf - b.conf).abs().max()) <= 1e-5
    two_a, two_b = TwoStageDetector(pt, min_side=32), TwoStageDetector(fast, min_side=32)
    big = DetectContext.of_images(_images(2, 128))
    ka = np.stack([d.keypoints[0] for d in two_a.detect(big)])
    kb = np.stack([d.keypoints[0] for d in two_b.detect(big)])
    assert np.abs(ka - kb).max() <= 1e-3


def test_the_gradient_path_stays_on_torch(cache, pt):
    fast = with_engine(pt, "onnxruntime", trust=True)
    grads = []
    for det in (pt, fast):
        x = _images(2).requires_grad_(True)
        det.top(x).keypoints.sum().backward()
        grads.append(x.grad)
    assert torch.equal(grads[0], grads[1])


def test_engine_names_and_identity(tiny_pose_pt):
    assert resolve_engine("auto") == "onnxruntime" and resolve_engine("torch") == "torch"
    with pytest.raises(ValueError, match="engine must be"):
        resolve_engine("tensorrt")
    a = DetectorSpec("ultralytics", str(tiny_pose_pt), trust=True)
    b = DetectorSpec("ultralytics", str(tiny_pose_pt), trust=True, options={"engine": "onnxruntime"})
    assert a.key() == b.key()  # same outputs: a run may resume on another engine
    assert a.identity()["engine"] == "torch" and b.identity()["engine"] == "onnxruntime"
    assert b.identity()["precision"] == "fp32"
