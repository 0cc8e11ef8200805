"""The torch twin of a user's ONNX export: it agrees with ONNX Runtime, APGD on it retraces APGD on the .pt, and a
twin that cannot be made or disagrees leaves the detector without gradients and says why."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import torch

import vbl_robust.detect.onnx_twin as twin_mod
from vbl_robust.campaigns.precheck import check_methods
from vbl_robust.constants import NotMeasuredError
from vbl_robust.detect.base import DetectContext
from vbl_robust.detect.onnx import OnnxDetector
from vbl_robust.detect.onnx_twin import (
    CONF_TOL,
    KEYPOINT_TOL_PX,
    TorchTwin,
    TwinPose,
    compare_raw,
    with_twin,
)
from vbl_robust.detect.shipped import DEFAULT_MODEL, DetectorSpec
from vbl_robust.pipeline import Objective
from vbl_robust.search.api import maximize
from vbl_robust.space import ParameterBox

IMGSZ = 320
BOX = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
BLACK_BOX = "georobust, georobust-a, georobust-av, direct, direct-l, random, sobol or grid"


@pytest.fixture(scope="module")
def user_onnx(tmp_path_factory):
    """The shipped model exported the way a user does (``yolo export format=onnx imgsz=320``: static batch 1,
    opset 18, Split v18 in the graph)."""
    from vbl_robust.detect.offline import import_ultralytics

    import_ultralytics()
    from ultralytics import YOLO

    work = tmp_path_factory.mktemp("user_onnx")
    shutil.copyfile(DEFAULT_MODEL, work / "my_model.pt")
    out = YOLO(str(work / "my_model.pt"), task="pose").export(format="onnx", imgsz=IMGSZ, verbose=False)
    return work / "my_model.onnx" if str(out).endswith("my_model.onnx") else out


@pytest.fixture(scope="module")
def sample():
    from vbl_robust.scenes.generate import generate

    return generate(1, seed=7, width=512, height=512)[0]


@pytest.fixture(scope="module")
def onnx_det(user_onnx):
    return DetectorSpec("onnx", str(user_onnx)).build()


def test_the_default_onnx_detector_has_a_checked_twin(onnx_det, user_onnx):
    assert isinstance(onnx_det, TwinPose) and onnx_det.differentiable and onnx_det.gradient_unavailable == ""
    assert isinstance(onnx_det.engine_model, OnnxDetector) and onnx_det.engine == "onnxruntime"
    assert onnx_det.torch_model.batch == 1  # ultralytics' default export: a static batch of one
    assert onnx_det.checks[0].ok and onnx_det.checks[0].keypoints_px <= KEYPOINT_TOL_PX
    check_methods(["apgd"], onnx_det, "my_model.onnx")  # no refusal: the twin gives the gradient
    # the identity a run records is the file's, as before: kind, SHA-256, engine
    ident = DetectorSpec("onnx", str(user_onnx)).identity()
    assert ident["kind"] == "onnx" and ident["engine"] == "onnxruntime" and len(ident["sha256"]) == 64


def test_twin_matches_onnx_runtime_on_a_rendered_view(onnx_det, sample):
    img = torch.from_numpy(np.asarray(sample.image, np.float32) / 255).permute(2, 0, 1)[None]
    ctx = DetectContext.of_images(img)
    views, _ = onnx_det.letterbox(ctx)
    with torch.no_grad():
        check = compare_raw(onnx_det.engine_model.raw(views), onnx_det.torch_model.raw(views), onnx_det.nc)
    assert check.ok, check.reason
    assert check.keypoints_px <= KEYPOINT_TOL_PX and check.conf <= CONF_TOL
    black = onnx_det.detect(ctx)[0]  # ONNX Runtime, NMS
    conf, kp = onnx_det.detect_top(DetectContext.of_images(img.requires_grad_(True)))  # the twin, with a gradient
    assert kp.requires_grad
    c = float(conf[0].detach())
    assert c == pytest.approx(float(black.conf[0]), abs=CONF_TOL) and c > 0.5
    assert np.abs(kp[0].detach().numpy() - black.keypoints[0]).max() <= KEYPOINT_TOL_PX


def test_apgd_on_the_onnx_retraces_apgd_on_the_pt(onnx_det, sample):
    from vbl_robust.detect.ultralytics import UltralyticsDetector

    pt = UltralyticsDetector(DEFAULT_MODEL, trust=True, imgsz=IMGSZ)
    runs = {}
    for name, det in (("onnx", onnx_det), ("pt", pt)):
        objective = Objective(sample, det, BOX)
        r = maximize(objective, BOX, "apgd", max_evals=8, seed=0, n_restarts=2)
        kp = objective.evaluate(torch.tensor(r.xs, requires_grad=True)).keypoints
        runs[name] = (r, kp)
    (ro, ko), (rp, kp) = runs["onnx"], runs["pt"]
    assert ro.nfev == rp.nfev == 8
    np.testing.assert_allclose(ro.xs, rp.xs, rtol=0, atol=1e-9)  # the same steps: the gradients' signs agree
    np.testing.assert_allclose(ro.x, rp.x, rtol=0, atol=1e-9)  # the same worst θ
    assert np.nanmax(np.abs(ko - kp)) <= KEYPOINT_TOL_PX  # sample px
    np.testing.assert_allclose(ro.fs, rp.fs, rtol=1e-4)  # metres; an error of ~2 km moves ~1e-5 of itself
    assert onnx_det.checks[-1].where == "first views of the run" and onnx_det.checks[-1].ok
    assert onnx_det.differentiable


def _refused(det, sample, match):
    assert not det.differentiable
    assert match in det.gradient_unavailable
    with pytest.raises(ValueError) as refused:  # before the run: one line that names the alternatives
        check_methods(["apgd"], det, "my_model.onnx")
    line = str(refused.value)
    assert "\n" not in line and line.startswith("--methods apgd: method unfit — the detector my_model.onnx gives no "
                                                "gradient (") and BLACK_BOX in line
    with pytest.raises(NotMeasuredError, match="gradient|differentiable"):
        maximize(Objective(sample, det, BOX), BOX, "apgd", max_evals=4, seed=0)


def test_a_converter_failure_leaves_the_detector_without_gradients(user_onnx, sample, monkeypatch):
    def broken(path):
        raise ValueError("onnx2pytorch cannot convert the graph (NotImplementedError: Split v18)")

    monkeypatch.setattr(twin_mod, "convert_onnx", broken)
    det = DetectorSpec("onnx", str(user_onnx)).build()
    assert isinstance(det, OnnxDetector)
    _refused(det, sample, "cannot convert the graph")
    assert len(det.detect(DetectContext.of_images(np.zeros((64, 64, 3), np.uint8)))) == 1  # black box unchanged
    assert DetectorSpec("onnx", str(user_onnx), options={"design": "twostage"}).build().differentiable is False


class _Shifted(torch.nn.Module):
    """A twin that is off by ``shift`` view pixels on every keypoint x."""

    def __init__(self, module, shift):
        super().__init__()
        self.module, self.shift = module, shift

    def forward(self, x):
        y = self.module(x).clone()
        y[:, 5::3] += self.shift
        return y


def test_a_twin_that_disagrees_is_refused_at_construction(user_onnx, sample, monkeypatch):
    real = twin_mod.convert_onnx
    monkeypatch.setattr(twin_mod, "convert_onnx", lambda path: _Shifted(real(path), 0.01))
    det = DetectorSpec("onnx", str(user_onnx)).build()
    _refused(det, sample, "disagrees with the engine on the synthetic check view (keypoints 0.01 px")


def test_a_twin_that_disagrees_on_the_first_image_stops_the_gradient_search(user_onnx, sample):
    det = with_twin(OnnxDetector(user_onnx))
    assert det.differentiable and det.checks[0].ok
    det.torch_model.module = _Shifted(det.torch_model.module, 0.01)  # wrong only from now on
    objective = Objective(sample, det, BOX)
    before = objective.evaluate(np.array([[0.0, 1.0]]))  # black box: ONNX Runtime, untouched
    with pytest.raises(ValueError, match="first views of the run"):
        maximize(objective, BOX, "apgd", max_evals=4, seed=0)
    assert not det.differentiable and "first views of the run" in det.gradient_unavailable
    with pytest.raises(ValueError, match="first views of the run|not differentiable"):  # refused from now on
        objective.evaluate(torch.zeros(1, 2, dtype=torch.float64, requires_grad=True) + torch.tensor([0.0, 1.0]))
    np.testing.assert_array_equal(objective.evaluate(np.array([[0.0, 1.0]])).loss, before.loss)


def test_a_static_batch_runs_in_groups_padded_to_its_size():
    class Static2(torch.nn.Module):
        def forward(self, x):
            assert x.shape[0] == 2
            return x.mean((2, 3))[..., None].expand(2, 3, 5) * torch.arange(1, 3.0)[:, None, None]

    class Engine:
        imgsz, nc, chunk, gives_sigma, input_size, device = 8, 1, 16, False, 8, "cpu"

    twin = TorchTwin(Static2(), Engine(), batch=2)
    views = torch.rand(3, 3, 8, 8, generator=torch.Generator().manual_seed(0))
    out = twin.raw(views)
    assert out.shape == (3, 3, 5)
    torch.testing.assert_close(out[2], views[2].mean((1, 2))[:, None].expand(3, 5))  # row 0 of the padded group
