"""Runway-corner detectors run by OpenVINO, always in fp32.

OpenVINO compiles an ultralytics pose export (``.onnx``) or its own IR (``.xml`` + ``.bin``) for the CPU. On
CPUs with AVX-512 BF16 / AMX its *default* inference precision is bf16, which moved keypoints by up to 3 px at
320 px here (issue 13): this adapter always sets ``INFERENCE_PRECISION_HINT = f32`` and reads the precision back
from the compiled model (``precision``), so the model under test stays the model. No gradients: the
differentiable path stays in torch (:mod:`.engines`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from .onnx import pose_metadata
from .pose import PoseDetector

__all__ = ["OpenVinoDetector"]


class OpenVinoDetector(PoseDetector):
    """A YOLO-pose export (``.onnx`` or OpenVINO ``.xml``) compiled by OpenVINO for the CPU, fp32.

    Args:
        path: ``.onnx`` (an ultralytics pose export, dynamic batch) or ``.xml`` IR.
        imgsz: input side; None → the ``imgsz`` in the model's metadata (ONNX) or its static input shape.
        chunk: views per inference call.
        threads: inference threads (None: OpenVINO's default).
        device: ``cpu`` only (``auto`` means the CPU here): this project runs OpenVINO on its CPU plugin, fp32.
    """

    differentiable = False
    gradient_unavailable = "OpenVINO gives no gradients (with_twin adds a checked torch twin)"

    def __init__(self, path: str | Path, *, imgsz: int | None = None, chunk: int = 16,
                 threads: int | None = None, device: str = "cpu") -> None:
        import openvino as ov

        p = Path(path)
        if str(device).lower() not in ("cpu", "auto"):
            raise ValueError(f"{p}: the OpenVINO engine runs on the CPU only, got device {device!r} "
                             "(use --engine torch or onnxruntime on a GPU)")
        self.device = torch.device("cpu")
        if not p.is_file():
            raise FileNotFoundError(f"{p}: model file not found")
        core = ov.Core()
        try:
            model = core.read_model(str(p))
        except Exception as e:  # noqa: BLE001 - any OpenVINO read failure means the same to the user
            raise ValueError(f"{p}: not a model OpenVINO can read ({type(e).__name__}: {e})") from e
        # an ONNX export is checked like OnnxDetector does; an IR carries no such metadata (1 class assumed)
        self.nc, size = pose_metadata(p, _onnx_metadata(p)) if p.suffix.lower() == ".onnx" else (1, None)
        shape = model.inputs[0].get_partial_shape()
        static = shape[2].get_length() if shape.rank.get_length() == 4 and shape[2].is_static else None
        self.imgsz = int(imgsz or size or static or 640)
        config = {"INFERENCE_PRECISION_HINT": "f32"}
        if threads:
            config["INFERENCE_NUM_THREADS"] = int(threads)
        self.compiled = core.compile_model(model, "CPU", config)
        #: the precision the compiled model really runs at (checked: must be f32)
        self.precision = str(self.compiled.get_property("INFERENCE_PRECISION_HINT"))
        if "32" not in self.precision:
            raise ValueError(f"{p}: OpenVINO compiled at {self.precision}, not fp32; refusing (outputs would change)")
        self.request = self.compiled.create_infer_request()
        channels = self.compiled.outputs[0].get_partial_shape()[1]
        self.gives_sigma = channels.is_static and channels.get_length() == 4 + self.nc + 12 + 8
        self.input_size = self.imgsz
        self.chunk = int(chunk)
        self.path = p

    def __repr__(self) -> str:
        return f"OpenVinoDetector({str(self.path)!r}, imgsz={self.imgsz}, precision={self.precision})"

    def raw(self, views: torch.Tensor) -> torch.Tensor:
        x = np.ascontiguousarray(views.detach().cpu().numpy(), dtype=np.float32)
        y = self.request.infer({0: x})[self.compiled.outputs[0]]
        return torch.from_numpy(np.array(y)).to(views.device, views.dtype)


def _onnx_metadata(path: Path) -> dict[str, str]:
    import onnx

    m = onnx.load(str(path), load_external_data=False)
    return {p.key: p.value for p in m.metadata_props}
