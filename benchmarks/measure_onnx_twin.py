"""The torch twin of a user's ONNX export against ONNX Runtime, and APGD on the ``.onnx`` against APGD on the ``.pt``.

Exports the shipped model the way a user does (``yolo export format=onnx imgsz=320``: static batch 1, opset 18) into
a temporary directory, builds the detector ``--model my_model.onnx`` gets (:class:`~vbl_robust.detect.shipped.DetectorSpec`,
ONNX Runtime with its checked twin) and prints, on rendered approaches (``generate(n, seed=7)``, 512 × 512):

- per image, on three θ of roll ±15° × contrast [0.7, 1.4]: max |Δ| keypoint (view px, every anchor NMS could
  keep) and confidence between the twin and ONNX Runtime on the same views, and max |Δ| of the selected corners
  (sample px) between the differentiable path (twin) and the black box (ONNX Runtime);
- per image of the first ``--apgd``: APGD (12 evaluations, 2 restarts, seed 0) through
  :class:`~vbl_robust.pipeline.Objective` on the ``.onnx`` and on the ``.pt`` (torch): max |Δθ| of the evaluated
  points, max |Δ| of their values (metres) and of their corners (sample px), and both worst θ.

``python benchmarks/measure_onnx_twin.py [--images 6] [--apgd 3]`` (about 35 s on one core).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np
import torch


def export_like_a_user(out_dir: Path) -> Path:
    from vbl_robust.detect.offline import import_ultralytics
    from vbl_robust.detect.shipped import DEFAULT_MODEL

    import_ultralytics()
    from ultralytics import YOLO

    shutil.copyfile(DEFAULT_MODEL, out_dir / "my_model.pt")
    YOLO(str(out_dir / "my_model.pt"), task="pose").export(format="onnx", imgsz=320, verbose=False)
    return out_dir / "my_model.onnx"


def main(images: int = 6, apgd: int = 3) -> None:
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.onnx_twin import compare_raw
    from vbl_robust.detect.shipped import DEFAULT_MODEL, DetectorSpec
    from vbl_robust.detect.ultralytics import UltralyticsDetector
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.search.api import maximize
    from vbl_robust.space import ParameterBox

    setup_offline()
    torch.set_num_threads(1)
    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    theta = np.array([[0.0, 1.0], [10.0, 0.8], [-12.0, 1.3]])
    samples = generate(images, seed=7, width=512, height=512)
    with tempfile.TemporaryDirectory() as tmp:
        det = DetectorSpec("onnx", str(export_like_a_user(Path(tmp)))).build()
        print(f"detector: {det!r}; differentiable {det.differentiable}; construction check {det.checks[0]}")
        pt = UltralyticsDetector(DEFAULT_MODEL, trust=True, imgsz=320)
        worst = [0.0, 0.0, 0.0]
        for s in samples:
            objective = Objective(s, det, box)
            views, _ = det.letterbox(objective.context(theta))
            with torch.no_grad():
                c = compare_raw(det.engine_model.raw_chunked(views), det.torch_model.raw_chunked(views), det.nc)
            black = objective.evaluate(theta)
            white = objective.evaluate(torch.tensor(theta, requires_grad=True))
            top = float(np.nanmax(np.abs(black.keypoints - white.keypoints)))
            worst = [max(worst[0], c.keypoints_px), max(worst[1], c.conf), max(worst[2], top)]
            print(f"{s.id}: twin vs ONNX Runtime: keypoints {c.keypoints_px:.2e} view px, confidence {c.conf:.2e}; "
                  f"selected corners {top:.2e} sample px")
        print(f"max over {images} images: keypoints {worst[0]:.2e} view px, confidence {worst[1]:.2e}, selected "
              f"corners {worst[2]:.2e} sample px")
        for s in samples[:apgd]:
            runs = {}
            for name, d in (("onnx", det), ("pt", pt)):
                objective = Objective(s, d, box)
                r = maximize(objective, box, "apgd", max_evals=12, seed=0, n_restarts=2)
                runs[name] = (r, objective.evaluate(torch.tensor(r.xs, requires_grad=True)).keypoints)
            (ro, ko), (rp, kp) = runs["onnx"], runs["pt"]
            print(f"{s.id}: APGD .onnx vs .pt ({ro.nfev} evaluations): max |Δθ| {np.abs(ro.xs - rp.xs).max():.2e}, "
                  f"max |Δ value| {np.abs(ro.fs - rp.fs).max():.2e} m (worst {ro.fun:.1f} m), max |Δ corners| "
                  f"{np.nanmax(np.abs(ko - kp)):.2e} px; worst θ {ro.x.tolist()} / {rp.x.tolist()}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=6)
    ap.add_argument("--apgd", type=int, default=3)
    a = ap.parse_args()
    main(a.images, a.apgd)
