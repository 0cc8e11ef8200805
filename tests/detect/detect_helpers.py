"""Helpers for detector tests: tiny untrained YOLO-pose checkpoints and self-drawn runway images."""

from __future__ import annotations

import numpy as np
import torch


def _save_pose_ckpt(path, *, nk=4, imgsz=64, seed=0):
    from vbl_robust.detect.offline import import_ultralytics

    import_ultralytics()
    from ultralytics.nn.tasks import PoseModel

    torch.manual_seed(seed)  # test-only: ultralytics builds modules with the global generator
    m = PoseModel("yolov8n-pose.yaml", nc=1, data_kpt_shape=(nk, 3), verbose=False)
    m.names = {0: "runway"}
    m.args = {"imgsz": imgsz}
    # keep keypoints near their anchors (inside the image), so predict()'s border clipping does not hide them
    head = m.model[-1]
    for seq in head.cv4:
        seq[-1].weight.data.mul_(0.01)
        seq[-1].bias.data.uniform_(0.02, 0.15)
    torch.save({"model": m, "train_args": {"imgsz": imgsz, "task": "pose"}, "epoch": -1}, path)
    return path


def runway_image(size=64, seed=0):
    """(size, size, 3) uint8 RGB: a bright trapezoid on dark noise; returns (image, corners (4, 2) OpenCV px)."""
    import cv2

    rng = np.random.default_rng(seed)
    img = rng.integers(0, 60, (size, size, 3), dtype=np.uint8)
    c = size / 2 + rng.uniform(-0.2, 0.2, 2) * size
    w, h = 0.3 * size, 0.25 * size
    corners = np.array([[c[0] + w / 3, c[1] - h / 2], [c[0] - w / 3, c[1] - h / 2],
                        [c[0] - w / 2, c[1] + h / 2], [c[0] + w / 2, c[1] + h / 2]])
    cv2.fillPoly(img, [np.round((corners + 0.0) * 16).astype(np.int32)], (220, 220, 220), cv2.LINE_AA, shift=4)
    return img, corners


def approach_sample(size=128):
    """A :class:`Sample` of :func:`runway_image` (seed 3) with the geometry of a 3° approach 2 km out."""
    from vbl_robust.data.sample import Sample
    from vbl_robust.geometry.camera import intrinsics, project, rot_y, runway_corners

    img, _ = runway_image(size, seed=3)
    K, z = intrinsics(size, size), runway_corners(3000.0, 45.0)
    C = np.array([-2000.0, 0.0, 2000.0 * np.tan(np.radians(3.0))])
    return Sample(id="s", K=K, corners_3d=z, corners_2d=project(z, rot_y(3.0), C, K), position=C, width=size,
                  height=size, _image=img)


def square_sample(seed=0, size=96):
    """A :class:`Sample` of :func:`runway_image` with its corners as labels (geometry irrelevant: training tests)."""
    from vbl_robust.data.sample import Sample
    from vbl_robust.geometry.camera import intrinsics

    img, c = runway_image(size, seed=seed)
    return Sample(id=f"s{seed}", K=intrinsics(size, size), corners_3d=np.zeros((4, 3)), corners_2d=c,
                  position=np.array([-1000.0, 0.0, 50.0]), width=size, height=size, _image=img)
