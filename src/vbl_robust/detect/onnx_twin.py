"""Gradients for an ONNX pose model: a torch twin of the graph, checked against the engine before it is trusted.

ONNX Runtime and OpenVINO give no gradients, so a gradient search (APGD) could not run on a user's ``.onnx``.
:func:`with_twin` converts the graph to a torch module (``onnx2pytorch.ConvertModel(model, experimental=True)``;
``onnx2torch`` fails on ultralytics' exports, whose ``Split`` is opset 18) and composes it with the engine as
:class:`~vbl_robust.detect.engines.EnginePose` does for a ``.pt``: the engine runs every forward without a gradient
(the black-box path, so its results stay exactly the engine's), the twin only the forwards that need one.

The twin is trusted only after it agrees with the engine (the converter warns that some of its ops "might differ"):

* when it is built, on a deterministic synthetic view (:func:`check_view`), and its gradient w.r.t. the input must be
  finite there — a failure leaves the engine's detector as it was (``differentiable = False``) with the reason in
  ``gradient_unavailable``, so a command can refuse APGD before it runs;
* once more on the first views a gradient forward receives (the run's own first image): a disagreement there
  makes the detector non-differentiable and raises ``ValueError`` with the reason (the job is not measured; it is
  never scored on a twin that disagrees).

Agreement (:func:`compare_raw`): confidences of every anchor within :data:`CONF_TOL` and the keypoints of every
anchor NMS could keep (confidence ≥ ``conf_min`` in either output) and of each view's top anchor within
:data:`KEYPOINT_TOL_PX` view pixels (σ channels too, when the network has them). A static batch (ultralytics'
default export: 1) is met by running the twin on that many views at a time.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..constants import NotMeasured, NotMeasuredError
from .engines import EnginePose
from .pose import PoseDetector, split_raw, split_sigma

logger = logging.getLogger(__name__)

__all__ = ["CONF_TOL", "KEYPOINT_TOL_PX", "TorchTwin", "TwinCheck", "TwinPose", "check_view", "compare_raw",
           "convert_onnx", "with_twin"]

#: largest |Δ| keypoint (view pixels) between the twin and the engine for the twin to be trusted
KEYPOINT_TOL_PX = 1e-3
#: largest |Δ| confidence between the twin and the engine
CONF_TOL = 1e-4


@dataclass(frozen=True)
class TwinCheck:
    """One comparison of the twin with the engine on the same views.

    Attributes:
        where: which views (``"synthetic view"``, ``"first views of the run"``).
        keypoints_px: max |Δ| of the compared keypoints, view pixels (σ included when present).
        conf: max |Δ| confidence over all anchors.
        reason: ``""`` when within tolerance, else one line why not.
    """

    where: str
    keypoints_px: float
    conf: float
    reason: str = ""

    @property
    def ok(self) -> bool:
        return not self.reason


def compare_raw(engine: torch.Tensor, twin: torch.Tensor, nc: int, *, conf_min: float = 0.01,
                where: str = "views") -> TwinCheck:
    """Compare raw predictions ``(B, C, A)`` of the engine and of the twin (see the module docstring)."""
    if tuple(engine.shape) != tuple(twin.shape):
        return TwinCheck(where, float("inf"), float("inf"),
                         f"the torch twin's output has shape {tuple(twin.shape)}, the engine's {tuple(engine.shape)}")
    e, t = engine.detach().double().cpu(), twin.detach().double().cpu()
    _, ce, ke = split_raw(e, nc)
    _, ct, kt = split_raw(t, nc)
    dconf = float((ce - ct).abs().max()) if ce.numel() else 0.0
    keep = (ce >= conf_min) | (ct >= conf_min)
    keep[torch.arange(ce.shape[0]), ce.argmax(1)] = True
    dk = (ke - kt).abs()[keep]
    se, st = split_sigma(e, nc), split_sigma(t, nc)
    if se is not None:
        dk = torch.cat([dk.reshape(-1), (se - st).abs()[keep].reshape(-1)])
    dkp = float(dk.max()) if dk.numel() else 0.0
    reason = ""
    if not (np.isfinite(dkp) and np.isfinite(dconf)):
        reason = f"the torch twin's outputs are not finite on the {where}"
    elif dkp > KEYPOINT_TOL_PX or dconf > CONF_TOL:
        reason = (f"the torch twin disagrees with the engine on the {where} (keypoints {dkp:.2g} px, confidence "
                  f"{dconf:.2g}; tolerance {KEYPOINT_TOL_PX:g} px, {CONF_TOL:g})")
    return TwinCheck(where, dkp, dconf, reason)


def check_view(size: int) -> torch.Tensor:
    """A deterministic synthetic view ``(1, 3, size, size)`` in [0, 1]: a bright runway-like trapezoid on dark noise
    (the check at construction, before any image of a run is known)."""
    g = torch.Generator().manual_seed(0)
    img = torch.rand(3, size, size, generator=g) * 0.25
    v, u = torch.meshgrid(torch.arange(size, dtype=torch.float32) + 0.5,
                          torch.arange(size, dtype=torch.float32) + 0.5, indexing="ij")
    top, bottom = 0.40 * size, 0.70 * size
    half = 0.05 * size + (v - top) / (bottom - top) * 0.20 * size  # half width, growing towards the camera
    inside = (v >= top) & (v <= bottom) & ((u - size / 2).abs() <= half)
    img[:, inside] = torch.tensor([0.85, 0.85, 0.82])[:, None]
    return img[None]


def convert_onnx(path: str | Path) -> torch.nn.Module:
    """The ONNX file as a torch module (``onnx2pytorch``, experimental mode), in eval mode, its parameters frozen.

    Raises:
        ValueError: one line: the converter is missing or cannot convert the graph.
    """
    with warnings.catch_warnings():  # its import's deprecations, its "Result might differ": what the check measures
        warnings.simplefilter("ignore")
        try:
            import onnx
            from onnx2pytorch import ConvertModel
        except ImportError as e:
            raise ValueError(f"the ONNX-to-torch converter is not installed (pip install onnx2pytorch==0.6.0): "
                             f"{e}") from e
        try:
            module = ConvertModel(onnx.load(str(path)), experimental=True)
        except Exception as e:  # noqa: BLE001 - any converter failure means the same to the user: no twin
            detail = " ".join(str(e).split())[:200]
            raise ValueError(f"onnx2pytorch cannot convert the graph ({type(e).__name__}: {detail})") from e
    module.eval()
    for q in module.parameters():
        q.requires_grad_(False)
    return module


class TorchTwin(PoseDetector):
    """A converted ONNX graph as a torch :class:`~vbl_robust.detect.pose.PoseDetector` (the differentiable half of a
    :class:`TwinPose`); ``batch``: the graph's static batch (views run that many at a time, the last group padded),
    None for a dynamic batch."""

    def __init__(self, module: torch.nn.Module, engine: PoseDetector, batch: int | None) -> None:
        self.device = torch.device(getattr(engine, "device", "cpu"))
        self.module = module.to(self.device)
        self.batch = batch
        self.imgsz, self.nc, self.chunk = engine.imgsz, engine.nc, engine.chunk
        self.gives_sigma, self.input_size = engine.gives_sigma, engine.input_size
        self.path = getattr(engine, "path", None)

    def __repr__(self) -> str:
        return f"TorchTwin({str(self.path)!r})"

    def _forward(self, x: torch.Tensor) -> torch.Tensor:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # the converter's indexing and "might differ" notices
            out = self.module(x)
        return out[0] if isinstance(out, (tuple, list)) else out

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        x = views.to(self.device)
        if self.batch is None:
            return self._forward(x).to(views.device)
        parts = []
        for v in x.split(self.batch):
            n = v.shape[0]
            if n < self.batch:  # a static batch: pad with the last view, keep the real rows
                v = torch.cat([v, v[-1:].expand(self.batch - n, *v.shape[1:])])
            parts.append(self._forward(v)[:n])
        return torch.cat(parts).to(views.device)


class TwinPose(EnginePose):
    """An ONNX model on its engine (black box) with a checked torch twin for the forwards that need a gradient.

    ``checks``: the :class:`TwinCheck` of construction and, after the first gradient forward, of the run's first
    views. ``gradient_unavailable``: ``""`` while the twin is trusted, else why not (then ``differentiable`` is
    False and a gradient forward raises ``ValueError``).
    """

    def __init__(self, twin: TorchTwin, engine_model: PoseDetector, engine: str, check: TwinCheck) -> None:
        super().__init__(twin, engine_model, engine)
        self.path = getattr(engine_model, "path", None)
        self.checks: list[TwinCheck] = [check]
        self.differentiable = True
        self.gradient_unavailable = ""
        self._checked_run = False

    def __repr__(self) -> str:
        return f"TwinPose({self.engine_model!r}, engine={self.engine}, twin checked)"

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        if not (torch.is_grad_enabled() and views.requires_grad):
            return self.engine_model.raw(views)
        if self.gradient_unavailable:
            raise NotMeasuredError(NotMeasured.METHOD_UNFIT, f"{self.path.name}: no gradient: {self.gradient_unavailable}")
        if not self._checked_run:
            self._check_run(views.detach())
        return self.torch_model.raw(views)

    def _check_run(self, views: torch.Tensor) -> None:
        """Compare the twin with the engine once, on the first views a gradient forward receives."""
        with torch.no_grad():
            check = compare_raw(self.engine_model.raw(views), self.torch_model.raw(views), self.nc,
                                conf_min=self.conf_min, where="first views of the run")
        self.checks.append(check)
        self._checked_run = True
        if not check.ok:
            self.differentiable = False
            self.gradient_unavailable = check.reason
            raise NotMeasuredError(NotMeasured.METHOD_UNFIT, f"{self.path.name}: no gradient: {check.reason}")
        logger.info("%s: torch twin agrees with %s on the run's first views (%.2g px, confidence %.2g)",
                    self.path, self.engine, check.keypoints_px, check.conf)


def _static_batch(path: Path) -> int | None:
    import onnx

    dims = onnx.load(str(path), load_external_data=False).graph.input[0].type.tensor_type.shape.dim
    return int(dims[0].dim_value) if dims and dims[0].HasField("dim_value") and dims[0].dim_value > 0 else None


def with_twin(detector: PoseDetector, engine: str = "onnxruntime") -> PoseDetector:
    """``detector`` (an :class:`~vbl_robust.detect.onnx.OnnxDetector` or
    :class:`~vbl_robust.detect.openvino.OpenVinoDetector` of an ``.onnx`` file) with a checked torch twin for its
    gradient forwards (:class:`TwinPose`), or ``detector`` itself, still non-differentiable, with the one-line reason
    in ``gradient_unavailable`` when the graph cannot be converted or the twin fails its check (module docstring).
    """
    path = Path(getattr(detector, "path", ""))
    try:
        if path.suffix.lower() != ".onnx":
            raise ValueError(f"a torch twin is made from an .onnx file, not {path.name or type(detector).__name__}")
        twin = TorchTwin(convert_onnx(path), detector, _static_batch(path))
        view = check_view(detector.imgsz).to(twin.device)
        with torch.no_grad():
            check = compare_raw(detector.raw(view), twin.raw(view), detector.nc, conf_min=detector.conf_min,
                                where="synthetic check view")
        if check.ok:
            x = view.clone().requires_grad_(True)
            with torch.enable_grad():
                (grad,) = torch.autograd.grad(split_raw(twin.raw(x), detector.nc)[1].max(), x)
            if not bool(torch.isfinite(grad).all()):
                check = TwinCheck(check.where, check.keypoints_px, check.conf,
                                  "the torch twin's gradient is not finite on the synthetic check view")
    except Exception as e:  # noqa: BLE001 - no twin for any reason: the detector stays a black box, with the reason
        why = (str(e) if isinstance(e, ValueError) else f"{type(e).__name__}: {e}").strip()
        check = TwinCheck("synthetic check view", float("nan"), float("nan"),
                          why.splitlines()[0] if why else type(e).__name__)
    if check.ok:
        logger.info("%s: torch twin agrees with %s on a synthetic view (%.2g px, confidence %.2g)", path, engine,
                    check.keypoints_px, check.conf)
        return TwinPose(twin, detector, engine, check)
    detector.gradient_unavailable = f"no checked torch twin of {path.name}: {check.reason}"
    logger.info("%s: gradient searches unavailable: %s", path, check.reason)
    return detector
