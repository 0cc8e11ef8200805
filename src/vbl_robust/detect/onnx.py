"""Runway-corner detectors from ONNX files, run with ONNX Runtime (no pickle, hence no trust flag).

The ONNX graph is an ultralytics pose export (``dynamic=True``): input ``images`` (B, 3, S, S) float RGB in
[0, 1], output (B, 4 + nc + K·3, A), the same layout as the ``.pt`` raw predictions, so all pre- and
post-processing is shared with :class:`~vbl_robust.detect.pose.PoseDetector`. A model with a keypoint-uncertainty
head (YOLO26-pose) is exported with its σ channels appended (B, 4 + nc + K·3 + K·2, A): ultralytics' exporter
drops that head, so :func:`export_onnx` traces :class:`~vbl_robust.detect.ultralytics.PoseWithSigma` itself
(``torch.onnx.export``) and writes the same metadata. ONNX Runtime does not give
gradients: :meth:`OnnxDetector.top` works as a (non-differentiable) black box. The detector a run builds from an
``.onnx`` (:class:`~vbl_robust.detect.DetectorSpec`) adds a torch twin of the graph for gradient searches, checked
against ONNX Runtime before it is used (:mod:`.onnx_twin`).
"""

from __future__ import annotations

import ast
import logging
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import torch

from .offline import import_ultralytics
from .pose import PoseDetector
from .ultralytics import PoseWithSigma, has_sigma_head, load_pose_model

logger = logging.getLogger(__name__)


def export_onnx(pt_path: str | Path, out_path: str | Path, *, trust: bool = False, imgsz: int | None = None) -> Path:
    """Export an ultralytics pose ``.pt`` to ONNX with dynamic batch (``dynamic=True``); returns ``out_path``.

    ``trust`` as for :class:`~vbl_robust.detect.ultralytics.UltralyticsDetector` (the ``.pt`` is unpickled).
    """
    model, ckpt = load_pose_model(pt_path, trust=trust)  # checks trust, pose head, 4 keypoints
    import_ultralytics()
    from ultralytics import YOLO

    size = imgsz or (ckpt.get("train_args") or {}).get("imgsz", 640)
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    if has_sigma_head(model):
        return _export_with_sigma(model, out_path, int(size))
    # ultralytics writes next to the .pt: export from a copy in a directory of this call's own, so the source
    # directory is untouched and two exports at once never share a file; the result is moved in whole (atomic)
    work = Path(tempfile.mkdtemp(prefix=f".{out_path.stem}_", dir=out_path.parent))
    try:
        tmp = work / "export.pt"
        shutil.copyfile(pt_path, tmp)
        f = YOLO(str(tmp), task="pose").export(format="onnx", imgsz=size, dynamic=True, simplify=True,
                                               verbose=False)
        Path(f).replace(out_path)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out_path


def _export_with_sigma(model: torch.nn.Module, out_path: Path, size: int) -> Path:
    """Trace a YOLO26-pose model with its σ channels (:class:`PoseWithSigma`) to ONNX (dynamic batch, opset 17)
    with ultralytics' metadata keys; written beside ``out_path`` and moved in whole."""
    import onnx

    names, kpt_shape = dict(model.names), list(model.model[-1].kpt_shape)
    net = PoseWithSigma(model).eval()
    fd, tmp = tempfile.mkstemp(prefix=f".{out_path.stem}_", suffix=".onnx", dir=out_path.parent)
    try:
        os.close(fd)
        with torch.no_grad(), warnings.catch_warnings():  # the anchors of the fixed input size are constants: fine
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            torch.onnx.export(net, (torch.zeros(1, 3, size, size),), tmp, input_names=["images"],
                              output_names=["output0"], dynamic_axes={"images": {0: "batch"}, "output0": {0: "batch"}},
                              opset_version=17, dynamo=False)
        graph = onnx.load(tmp)
        meta = {"task": "pose", "imgsz": str([size, size]), "names": str(names), "kpt_shape": str(kpt_shape),
                "stride": str(int(max(net.stride))), "batch": "1", "keypoint_sigma": "xy view pixels, after the keypoints"}
        for key, value in meta.items():
            graph.metadata_props.add(key=key, value=value)
        onnx.save(graph, tmp)
        Path(tmp).replace(out_path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return out_path


def pose_metadata(path: Path, meta: dict[str, str]) -> tuple[int, int | None]:
    """``(classes, imgsz or None)`` from an ultralytics pose export's metadata; ``ValueError`` naming the file when
    it is not a 4-keypoint pose model."""
    kpt = meta.get("kpt_shape")
    if kpt is None:
        raise ValueError(f"{path}: no 'kpt_shape' in the ONNX metadata; not an ultralytics pose export")
    kpt_shape = ast.literal_eval(kpt)
    if int(kpt_shape[0]) != 4:
        raise ValueError(f"{path}: pose model has {kpt_shape[0]} keypoints; runway corners need 4")
    nc = max(1, len(ast.literal_eval(meta.get("names", "{0: 'runway'}"))))
    size = ast.literal_eval(meta.get("imgsz", "None"))
    return nc, (size if isinstance(size, int) or size is None else max(size))


class OnnxDetector(PoseDetector):
    """A YOLO-pose ONNX export as a runway-corner detector (black box).

    Args:
        path: ``.onnx`` file (e.g. from :func:`export_onnx` or ``yolo export format=onnx dynamic=True``).
        imgsz: input side; None → the ``imgsz`` stored in the file's metadata.
        chunk: images per inference call.
        threads: ONNX Runtime intra-op threads (None: its default).
        device: ``cpu`` (CPU provider) or ``cuda[:N]`` (ONNX Runtime's CUDA provider, which must be installed:
            ``onnxruntime-gpu``); ``auto`` → CUDA when torch sees one and the provider is installed.
    """

    differentiable = False
    gradient_unavailable = "ONNX Runtime gives no gradients (with_twin adds a checked torch twin)"

    def __init__(self, path: str | Path, *, imgsz: int | None = None, chunk: int = 16,
                 threads: int | None = None, device: str = "cpu") -> None:
        import onnxruntime as ort

        from .device import resolve_device

        p = Path(path)
        if not p.is_file():
            raise FileNotFoundError(f"{p}: ONNX file not found")
        opts = ort.SessionOptions()
        if threads:
            opts.intra_op_num_threads = int(threads)
        cuda_ok = "CUDAExecutionProvider" in ort.get_available_providers()
        wanted = resolve_device("cuda" if device == "auto" and cuda_ok else ("cpu" if device == "auto" else device))
        if wanted.startswith("cuda") and not cuda_ok:
            raise ValueError(f"{p}: ONNX Runtime on {wanted} needs its CUDA provider (pip install onnxruntime-gpu); "
                             f"installed providers: {', '.join(ort.get_available_providers())}")
        providers: list = ["CPUExecutionProvider"]
        if wanted.startswith("cuda"):
            providers = [("CUDAExecutionProvider", {"device_id": int(wanted.partition(":")[2])}), *providers]
        self.device = torch.device(wanted)
        try:
            self.session = ort.InferenceSession(str(p), opts, providers=providers)
        except Exception as e:  # noqa: BLE001 - any ORT load failure means the same to the user
            raise ValueError(f"{p}: not a loadable ONNX model ({type(e).__name__}: {e})") from e
        self.nc, size = pose_metadata(p, self.session.get_modelmeta().custom_metadata_map)
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        out_shape = self.session.get_outputs()[0].shape
        if len(out_shape) == 3 and isinstance(out_shape[2], int) and out_shape[2] == 6 + 12:
            raise ValueError(f"{p}: end-to-end (NMS-free) output layout is not supported")
        self.gives_sigma = len(out_shape) == 3 and out_shape[1] == 4 + self.nc + 12 + 8
        self.imgsz = int(imgsz or size or 640)
        if not isinstance(inp.shape[0], str) and not isinstance(inp.shape[2], str):
            if imgsz is not None and int(inp.shape[2]) != self.imgsz:
                raise ValueError(f"{p}: static input size {inp.shape[2]}, got imgsz={imgsz}")
            self.chunk = int(inp.shape[0])
        else:
            self.chunk = int(chunk)
        self.input_size = self.imgsz
        self.path = p

    def __repr__(self) -> str:
        return f"OnnxDetector({str(self.path)!r}, imgsz={self.imgsz})"

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        x = views.detach().cpu().numpy().astype(np.float32, copy=False)
        y = self.session.run(None, {self.input_name: x})[0]
        return torch.from_numpy(y).to(views.device, views.dtype)
