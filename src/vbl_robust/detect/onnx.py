"""Runway-corner detectors from ONNX files, run with ONNX Runtime (no pickle, hence no trust flag).

The ONNX graph is an ultralytics pose export (``dynamic=True``): input ``images`` (B, 3, S, S) float RGB in
[0, 1], output (B, 4 + nc + K·3, A), the same layout as the ``.pt`` raw predictions, so all pre- and
post-processing is shared with :class:`~vbl_robust.detect.pose.PoseDetector`. A model with a keypoint-uncertainty
head (YOLO26-pose) is exported with its σ channels appended (B, 4 + nc + K·3 + K·2, A): ultralytics' exporter
drops that head, so :func:`export_onnx` traces :class:`~vbl_robust.detect.ultralytics.PoseWithSigma` itself
(``torch.onnx.export``) and writes the same metadata. ONNX Runtime does not give
gradients: :meth:`OnnxDetector.top` works as a (non-differentiable) black box. The detector a run builds from an
``.onnx`` (:class:`~vbl_robust.detect.shipped.DetectorSpec`) adds a torch twin of the graph for gradient searches, checked
against ONNX Runtime before it is used (:mod:`.onnx_twin`).
"""

from __future__ import annotations

import ast
import logging
import os
import shutil
import tempfile
import warnings
from collections.abc import Sequence
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


#: Longest metadata value read (``kpt_shape``, ``names``, ``imgsz``): an export writes a few dozen characters.
MAX_METADATA_CHARS = 100_000


def _literal(path: Path, key: str, text: str) -> object:
    """The Python literal of metadata ``key`` (``ast.literal_eval``: no code runs), or ``ValueError`` naming the
    file, the key and the value."""
    shown = text if len(text) <= 40 else text[:37] + "..."
    if len(text) > MAX_METADATA_CHARS:
        raise ValueError(f"{path}: ONNX metadata {key!r} is longer than {MAX_METADATA_CHARS} characters")
    try:
        return ast.literal_eval(text)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        raise ValueError(f"{path}: ONNX metadata {key} = {shown!r} is not readable (a Python literal such as "
                         "[4, 3])") from None


def pose_metadata(path: Path, meta: dict[str, str]) -> tuple[int, int | None]:
    """``(classes, imgsz or None)`` from an ultralytics pose export's metadata; ``ValueError`` naming the file, the
    key and the value when it is not a 4-keypoint pose model (``kpt_shape`` [4, 3]: x, y, visibility per corner) or
    its ``names`` / ``imgsz`` cannot be read."""
    kpt = meta.get("kpt_shape")
    if kpt is None:
        raise ValueError(f"{path}: no 'kpt_shape' in the ONNX metadata; not an ultralytics pose export")
    kpt_shape = _literal(path, "kpt_shape", kpt)
    if not (isinstance(kpt_shape, list | tuple) and len(kpt_shape) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in kpt_shape)):
        raise ValueError(f"{path}: ONNX metadata kpt_shape = {kpt!r}: expected [keypoints, values per keypoint], "
                         "e.g. [4, 3]")
    if kpt_shape[0] != 4:
        raise ValueError(f"{path}: pose model has {kpt_shape[0]} keypoints; runway corners need 4")
    if kpt_shape[1] != 3:
        raise ValueError(f"{path}: pose model has {kpt_shape[1]} values per keypoint; the layout read here is x, y, "
                         "visibility (kpt_shape [4, 3])")
    names = _literal(path, "names", meta.get("names", "{0: 'runway'}"))
    if not isinstance(names, dict | list | tuple):
        raise ValueError(f"{path}: ONNX metadata names = {meta.get('names')!r}: expected the class names "
                         "({0: 'runway'})")
    nc = max(1, len(names))
    size = _literal(path, "imgsz", meta.get("imgsz", "None"))
    if isinstance(size, list | tuple) and size and all(isinstance(v, int) for v in size):
        size = max(size)
    if size is not None and not (isinstance(size, int) and not isinstance(size, bool) and 0 < size <= 8192):
        raise ValueError(f"{path}: ONNX metadata imgsz = {meta.get('imgsz')!r}: expected a side in pixels (1 to "
                         "8192) or [height, width]")
    return nc, size


def check_output_shape(path: Path, shape: Sequence[object], nc: int) -> bool:
    """Whether an output of ``shape`` — (B, 4 + nc + 12, A), or with the 8 σ channels of an uncertainty head
    (B, 4 + nc + 20, A); a dimension may be symbolic (a name, or None) — gives σ; ``ValueError`` naming the file
    and the shape for any other (a model that would fail every evaluation is refused when it is loaded)."""
    plain, sigma = 4 + nc + 12, 4 + nc + 20
    layout = f"(batch, {plain} or {sigma} channels: 4 box + {nc} class + 12 keypoint [+ 8 σ], anchors)"
    if len(shape) != 3:
        raise ValueError(f"{path}: output shape {list(shape)}: expected {layout}")
    channels, anchors = shape[1], shape[2]
    if isinstance(anchors, int) and anchors == 6 + 12:
        raise ValueError(f"{path}: end-to-end (NMS-free) output layout is not supported")
    if isinstance(channels, int) and channels not in (plain, sigma):
        raise ValueError(f"{path}: output shape {list(shape)}: {channels} channels, expected {layout}")
    if isinstance(anchors, int) and anchors < 1:
        raise ValueError(f"{path}: output shape {list(shape)}: no anchors")
    return channels == sigma


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
        if len(inp.shape) != 4 or (isinstance(inp.shape[1], int) and inp.shape[1] != 3):
            raise ValueError(f"{p}: input shape {list(inp.shape)}: expected (batch, 3, side, side) RGB views")
        out_shape = self.session.get_outputs()[0].shape
        self.gives_sigma = check_output_shape(p, out_shape, self.nc)
        self.imgsz = int(imgsz or size or 640)
        if not isinstance(inp.shape[0], str) and not isinstance(inp.shape[2], str):
            if imgsz is not None and int(inp.shape[2]) != self.imgsz:
                raise ValueError(f"{p}: static input size {inp.shape[2]}, got imgsz={imgsz}")
            self.chunk = int(inp.shape[0])
        else:
            self.chunk = int(chunk)
        self.input_size = self.imgsz
        self.path = p
        if not all(isinstance(d, int) for d in out_shape[1:]):
            # a symbolic channel count: the layout is known only from a forward pass
            self._probe(self.chunk if isinstance(inp.shape[0], int) else 1)

    def _probe(self, batch: int) -> None:
        """One forward pass on blank views: the output's layout checked (:func:`check_output_shape`) before any
        job runs, where the graph's declared shape leaves it open."""
        x = np.zeros((batch, 3, self.imgsz, self.imgsz), np.float32)
        try:
            y = self.session.run(None, {self.input_name: x})[0]
        except Exception as e:  # noqa: BLE001 - ORT's errors have many types; each means the same here
            raise ValueError(f"{self.path}: cannot run on a {list(x.shape)} input ({type(e).__name__}: "
                             f"{str(e).strip().splitlines()[0] if str(e).strip() else ''})") from None
        self.gives_sigma = check_output_shape(self.path, y.shape, self.nc)

    def __repr__(self) -> str:
        return f"OnnxDetector({str(self.path)!r}, imgsz={self.imgsz})"

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        x = views.detach().cpu().numpy().astype(np.float32, copy=False)
        y = self.session.run(None, {self.input_name: x})[0]
        return torch.from_numpy(y).to(views.device, views.dtype)
