"""An example detector plug-in: your own inference code behind vbl-robust's Detector protocol.

Here the inference code is ultralytics' own predictor (``YOLO(weights).predict``: its letterbox, its NMS), not
vbl-robust's built-in pose detector — the shape of what you would write around any keypoint model (a network of
another family, a classical corner detector): read the perturbed images from the context, run your model, return one
``Detections`` per image with the four runway corners in the order TR, TL, BL, BR, in the context's pixels.

Run it (importing this file runs it: naming it on the command line is your consent)::

    vbl-robust audit --detector-plugin examples/predict_plugin.py:make_detector --n 2 --max-evals 20 --roll 10

``VBL_PLUGIN_WEIGHTS`` names the ``.pt`` to load (default: the model shipped with vbl-robust).
"""

from __future__ import annotations

import os

import numpy as np

from vbl_robust.detect import Detections
from vbl_robust.detect.shipped import DEFAULT_MODEL


class PredictDetector:
    """Runway corners from ``ultralytics.YOLO(weights).predict`` on the whole perturbed image."""

    input_size = 320  # the long side it wants: vbl-robust resizes the source to it before perturbing
    uses_pixels = True  # it reads the images (the oracle does not)
    differentiable = False  # no detect_top: gradient searches (apgd) are refused before the run

    def __init__(self, weights: str) -> None:
        from vbl_robust.detect.offline import import_ultralytics  # ultralytics offline: nothing downloaded

        import_ultralytics()
        from ultralytics import YOLO

        self.model = YOLO(weights, task="pose")

    def detect(self, context) -> list[Detections]:
        frames = context.frames()  # (B, 3, H, W) float in [0, 1]: the perturbed images
        images = [np.ascontiguousarray((f.permute(1, 2, 0).cpu().numpy() * 255).round().astype(np.uint8)[..., ::-1])
                  for f in frames]  # HWC BGR uint8, what ultralytics takes for numpy input
        out = []
        for result in self.model.predict(images, imgsz=self.input_size, conf=0.01, verbose=False):
            if result.keypoints is None or len(result.boxes) == 0:
                out.append(Detections.empty())
                continue
            out.append(Detections(boxes=result.boxes.xyxy.cpu().numpy(), conf=result.boxes.conf.cpu().numpy(),
                                  keypoints=result.keypoints.xy.cpu().numpy()[:, :4, :]))
        return out


def make_detector() -> PredictDetector:
    """The factory ``--detector-plugin`` calls (no argument)."""
    return PredictDetector(os.environ.get("VBL_PLUGIN_WEIGHTS", str(DEFAULT_MODEL)))
