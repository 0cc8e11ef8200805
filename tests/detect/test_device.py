"""The --device option: resolution, errors, and device placement of the view sampler.

No GPU here: the placement test makes the views on PyTorch's ``meta`` device, where an op that mixes a meta tensor
with a CPU tensor raises exactly as a CUDA/CPU mix would — so a tensor created on the wrong device in the sampler
or in a geometric family fails this test on the direct path (scaled windows: the two-stage design's views). Code
that reads values back (``.item()``, the frame path's integer-shift test, the contrast's clamps) cannot run on
``meta`` at all, which says nothing about CUDA; those paths are left out.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vbl_robust.perturb.compose import Perturbation
from vbl_robust.perturb.registry import PERTURBATIONS
from vbl_robust.perturb.resample import PixelScale
from vbl_robust.perturb.views import ViewSampler
from vbl_robust.space import ParameterBox

no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without CUDA")

META_FAMILIES = ("roll_deg", "pitch_deg", "yaw_deg", "haze")


def test_resolve_device_names():
    from vbl_robust.detect.device import resolve_device

    assert resolve_device("cpu") == "cpu"
    assert resolve_device(" CPU ") == "cpu"
    assert resolve_device("auto") == ("cuda:0" if torch.cuda.is_available() else "cpu")
    assert resolve_device(None) == resolve_device("auto")
    for bad in ("gpu", "cuda:x", "tpu:0", ""):
        with pytest.raises(ValueError, match="device"):
            resolve_device(bad)


@no_cuda
def test_cuda_refused_without_a_gpu():
    from vbl_robust.detect.device import resolve_device

    with pytest.raises(ValueError, match="no CUDA device"):
        resolve_device("cuda")
    with pytest.raises(ValueError, match="no CUDA device"):
        resolve_device("cuda:1")


def test_auto_engine_on_cuda_is_torch():
    from vbl_robust.detect.engines import installed_engines, resolve_engine

    assert resolve_engine("auto", "cuda:0") == "torch"
    assert resolve_engine("auto", "cpu") == ("onnxruntime" if "onnxruntime" in installed_engines() else "torch")


def test_openvino_refuses_a_gpu(tmp_path):
    from vbl_robust.detect.openvino import OpenVinoDetector

    f = tmp_path / "m.onnx"
    f.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="CPU only"):
        OpenVinoDetector(f, device="cuda")


@pytest.mark.parametrize("names", [(n,) for n in META_FAMILIES] + [META_FAMILIES])
@pytest.mark.parametrize("differentiable", [False, True])
def test_views_are_made_on_the_source_device(names, differentiable):
    h = w = 64
    img = np.random.default_rng(0).random((h, w, 3)).astype(np.float32)
    K = np.array([[60.0, 0, w / 2], [0, 60.0, h / 2], [0, 0, 1]])
    box = ParameterBox({n: PERTURBATIONS[n].default for n in names})
    theta = box.from_unit(np.random.default_rng(1).random((3, len(names))))
    if differentiable:
        theta = torch.tensor(theta, requires_grad=True)
    src = torch.from_numpy(img).permute(2, 0, 1)[None].to("meta")
    for window, size in (((0.0, 0.0, 64.0), 32), ((8.0, 8.0, 24.0), 32)):
        sampler = ViewSampler(Perturbation(box), src, theta, K=K, scale=PixelScale(), frame=img)
        views = sampler.views(torch.tensor(window), size)
        assert views.device.type == "meta"
        assert tuple(views.shape) == (3, 3, size, size)


def test_objective_follows_the_detector_device():
    from vbl_robust.detect.oracle import OracleDetector
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate

    sample = generate(1, seed=3)[0]
    box = ParameterBox({"roll_deg": (-5, 5)})
    det = OracleDetector()
    assert Objective(sample, det, box).device == torch.device("cpu")
    det.device = "cpu"
    assert Objective(sample, det, box, device="cpu").device.type == "cpu"
    with pytest.raises(ValueError, match="device"):
        Objective(sample, det, box, device="gpu")


def test_device_is_recorded_but_not_keyed():
    from vbl_robust.detect.shipped import DetectorSpec, default_model_path

    if default_model_path() is None:
        pytest.skip("shipped model not installed")
    plain, on_cpu = DetectorSpec("default"), DetectorSpec("default", options={"device": "cpu"})
    assert plain.key() == on_cpu.key()
    assert on_cpu.identity()["device"] == "cpu"


@no_cuda
def test_cli_refuses_cuda_without_a_gpu(tmp_path):
    from typer.testing import CliRunner

    from vbl_robust.cli import app

    res = CliRunner().invoke(app, ["audit", "--n", "1", "--device", "cuda", "--out", str(tmp_path / "r"), "-q"])
    assert res.exit_code != 0
    assert "--device cuda" in res.output and "no CUDA device" in res.output
