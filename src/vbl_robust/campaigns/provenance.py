"""Provenance of a run: code version, library versions, dataset identity, sample fingerprints.

The detector identity (model file SHA-256, design) is :meth:`DetectorSpec.identity`, defined with the shipped
model's rules in :mod:`vbl_robust.detect.shipped` and re-exported here.
"""

from __future__ import annotations

import subprocess
from collections.abc import Sequence
from functools import cache
from pathlib import Path
from typing import Any

from ..detect.shipped import (  # noqa: F401 - re-exported: campaigns name detectors by DetectorSpec
    DetectorSpec,
    default_model_caveats,
    default_model_info,
    default_model_path,
    default_model_status,
)
from ..digest import digest, file_sha256  # noqa: F401 - file_sha256 re-exported


@cache
def code_version() -> str:
    """``git describe --always --dirty`` of the source checkout when there is one, else the package version."""
    import vbl_robust

    src = Path(vbl_robust.__file__).resolve().parent
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=src, capture_output=True,
                             text=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return f"{vbl_robust.__version__}+git.{out.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    return vbl_robust.__version__


#: The libraries whose versions can move a result (the network, the warps, the PnP solvers, the inference engines).
NUMERIC_LIBRARIES = ("torch", "torchvision", "opencv-python", "opencv-python-headless", "numpy", "scipy", "kornia",
                     "ultralytics", "onnxruntime", "openvino", "onnx2pytorch")


@cache
def library_versions() -> dict[str, str]:
    """The installed versions of :data:`NUMERIC_LIBRARIES` (those installed): a run's provenance, since a result
    computed elsewhere (another machine, a GPU image) may differ in the last digits with them."""
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in NUMERIC_LIBRARIES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            continue
    return out


#: CPU flags that change which kernels numeric libraries pick (and so the last digits of their results).
SIMD_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512_vnni", "avx512_bf16", "amx_tile", "neon", "asimd")
#: Environment variables that set the thread counts of numeric libraries.
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def machine_identity() -> dict[str, Any]:
    """What moves a run's numerics from one machine to another, for its provenance: the CPU model and the SIMD
    instruction sets it offers (:data:`SIMD_FLAGS`, from ``/proc/cpuinfo`` where there is one), the cores this
    process may use, torch's intra-op threads and the thread variables of the environment. Two machines with the
    same wheels can still round differently when these differ (``reproduce --check-against`` calls that drift)."""
    import os
    import platform

    model, flags = platform.processor() or platform.machine(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                model = value.strip()
            elif key.strip() in ("flags", "Features"):
                flags.update(value.split())
    except OSError:
        pass
    try:
        import torch

        torch_threads: int | None = torch.get_num_threads()
    except ImportError:  # pragma: no cover - torch is a dependency
        torch_threads = None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"cpu": model, "simd": [f for f in SIMD_FLAGS if f in flags], "cores": cores,
            "torch_threads": torch_threads, "thread_env": {v: os.environ[v] for v in THREAD_VARS if v in os.environ},
            "python": platform.python_version(), "system": platform.system()}


def sample_fingerprint(sample: Any) -> str:
    """Digest of a sample's identity and geometry (id, size, K, corners 3D/2D, true position); of an approach
    sequence (a sample of a sequence campaign): its id, its frames' digests, frame indices and times."""
    frames = getattr(sample, "samples", None)
    if frames is not None:
        return digest({"id": sample.id, "frames": [sample_fingerprint(f) for f in frames],
                       "frame_index": [int(i) for i in sample.frame_index],
                       "times": [float(t) for t in sample.times]}, 16)
    return digest({
        "id": sample.id, "size": [int(sample.width), int(sample.height)], "K": sample.K.tolist(),
        "corners_3d": sample.corners_3d.tolist(), "corners_2d": sample.corners_2d.tolist(),
        "position": sample.position.tolist(),
    }, 16)


def dataset_identity(samples: Sequence[Any], source: dict[str, Any]) -> dict[str, Any]:
    """``{"source": ..., "n": ..., "sha256": ...}``: where the samples came from and a digest of all of them."""
    fps = [sample_fingerprint(s) for s in samples]
    return {"source": source, "n": len(samples), "sha256": digest(fps)}
