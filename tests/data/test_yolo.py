"""YOLO-pose label export: format, half-pixel convention, visibility, round trip."""

from __future__ import annotations

import numpy as np
import pytest

from vbl_robust.data.yolo import FLIP_IDX, parse_pose_label, pose_label, write_data_yaml, write_pose_images


def test_half_pixel_convention():
    # an OpenCV pixel centre u = 0 is half a pixel right of the image edge: x_norm = 0.5 / W
    c = np.array([[0.0, 0.0], [99.0, 0.0], [99.0, 49.0], [0.0, 49.0]])
    f = pose_label(c, 100, 50).split()
    k = np.array(f[5:], dtype=float).reshape(4, 3)
    assert k[0, :2] == pytest.approx([0.5 / 100, 0.5 / 50])
    assert k[2, :2] == pytest.approx([99.5 / 100, 49.5 / 50])
    assert np.array(f[1:5], dtype=float) == pytest.approx([0.5, 0.5, 0.99, 0.98])


def test_round_trip_and_outside_corners():
    c = np.array([[60.2, 10.7], [40.1, 10.7], [-5.0, 80.3], [70.9, 80.3]])
    line = pose_label(c, 100, 50)
    box, back, vis = parse_pose_label(line, 100, 50)
    assert vis.tolist() == [True, True, False, False]  # v = 0 outside the image
    assert back[:2] == pytest.approx(c[:2], abs=1e-4)
    assert np.isnan(back[2:]).all()
    assert box == pytest.approx([0.0, 11.2, 71.4, 50.0], abs=1e-4)  # clipped corner box, edge coordinates


def test_horizontal_flip_matches_flip_idx():
    """Mirroring the image (u → W − 1 − u) and permuting with flip_idx gives the mirrored runway's labels."""
    w, h = 100, 50
    c = np.array([[60.2, 10.7], [40.1, 10.7], [30.0, 40.3], [70.9, 40.3]])
    f = np.array(pose_label(c, w, h).split()[5:], dtype=float).reshape(4, 3)
    mirrored = c.copy()
    mirrored[:, 0] = w - 1 - c[:, 0]
    g = np.array(pose_label(mirrored[list(FLIP_IDX)], w, h).split()[5:], dtype=float).reshape(4, 3)
    flipped = f[list(FLIP_IDX)].copy()
    flipped[:, 0] = 1.0 - flipped[:, 0]  # ultralytics' fliplr on normalised edge coordinates
    assert g == pytest.approx(flipped, abs=1e-6)


def test_no_label_when_runway_outside():
    c = np.array([[-30.0, 10.0], [-40.0, 10.0], [-45.0, 20.0], [-25.0, 20.0]])
    assert pose_label(c, 100, 50) is None
    assert pose_label(np.full((4, 2), np.nan), 100, 50) is None


def test_write_dataset(tmp_path):
    img = np.zeros((32, 48, 3), np.uint8)
    c = np.array([[30.0, 5.0], [20.0, 5.0], [10.0, 25.0], [40.0, 25.0]])
    n = write_pose_images([("a", img, c), ("b", img, c + 100)], tmp_path, "train")
    assert n == 2
    assert (tmp_path / "images/train/a.png").exists()
    assert (tmp_path / "labels/train/a.txt").read_text().count("\n") == 1
    assert (tmp_path / "labels/train/b.txt").read_text() == ""
    y = write_data_yaml(tmp_path).read_text()
    assert f"path: {tmp_path.resolve()}" in y and "kpt_shape: [4, 3]" in y and "flip_idx: [1, 0, 3, 2]" in y
    assert "download" not in y
    with pytest.raises(ValueError, match="uint8"):
        write_pose_images([("c", img.astype(float), c)], tmp_path, "train")


def test_min_box_widens_tiny_boxes_keeps_keypoints():
    # a far runway: 3 × 8 px at detector resolution
    c = np.array([[51.0, 20.0], [49.0, 20.0], [48.0, 27.0], [52.0, 27.0]])
    plain, wide = pose_label(c, 100, 50), pose_label(c, 100, 50, min_box=24)
    assert plain.split()[5:] == wide.split()[5:]  # keypoints untouched
    box0, _, _ = parse_pose_label(plain, 100, 50)
    box, _, _ = parse_pose_label(wide, 100, 50)
    assert (box[:2] + box[2:]) / 2 == pytest.approx((box0[:2] + box0[2:]) / 2, abs=1e-5)  # same centre
    assert box[2:] - box[:2] == pytest.approx([24.0, 24.0], abs=1e-5)
    # a large box is unchanged; a widened box is clipped to the image
    big = np.array([[90.0, 5.0], [10.0, 5.0], [5.0, 45.0], [95.0, 45.0]])
    assert pose_label(big, 100, 50, min_box=24) == pose_label(big, 100, 50)
    edge = np.array([[2.0, 20.0], [0.0, 20.0], [0.0, 27.0], [3.0, 27.0]])
    box, _, _ = parse_pose_label(pose_label(edge, 100, 50, min_box=24), 100, 50)
    assert box[0] == pytest.approx(0.0) and box[2] == pytest.approx(2.0 + 12.0, abs=1e-5)
