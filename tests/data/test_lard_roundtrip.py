"""write_lard → read_lard gives back the samples; the CSV is in LARD V2 columns and units."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from lard_helpers import H, W, make_runway_db, make_samples

from vbl_robust.data.lard import LARD_COLUMNS, METRES_PER_NM
from vbl_robust.data.lard_read import read_lard
from vbl_robust.data.lard_write import write_lard


@pytest.fixture
def runway_db():
    return make_runway_db()


def test_round_trip_is_exact(tmp_path, runway_db):
    samples = make_samples(runway_db, n=6)
    csv_path = write_lard(tmp_path / "ds", samples, runway_db)
    back = read_lard(csv_path, tmp_path / "ds" / "runways_db.json")
    assert len(back) == len(samples)
    for s, r in zip(samples, back, strict=True):
        assert r.id == f"images/{s.id}.png"
        assert (r.width, r.height) == (W, H)
        np.testing.assert_allclose(r.K, s.K, rtol=1e-12)
        np.testing.assert_allclose(r.corners_3d, s.corners_3d, atol=1e-6)
        np.testing.assert_array_equal(r.corners_2d, s.corners_2d)  # exact columns, full precision
        assert np.linalg.norm(r.position - s.position) < 1e-3
        np.testing.assert_allclose(r.R, s.R, atol=1e-7)
        np.testing.assert_array_equal(r.image, s.image)  # png is lossless
        assert r.meta["airport"] == s.meta["airport"] and r.meta["runway"] == s.meta["runway"]
        assert r.meta["lard_check"] == {} and r.meta["corners_exact"] is True
        assert r.slant_distance_m == pytest.approx(s.slant_distance_m, abs=1e-3)


def test_csv_has_lard_columns_and_units(tmp_path, runway_db):
    samples = make_samples(runway_db, n=3)
    csv_path = write_lard(tmp_path, samples, runway_db, reference="VBLA at 43.6N 1.4E")
    with open(csv_path, newline="") as f:
        header = f.readline().rstrip("\n").split(";")
        f.seek(0)
        rows = list(csv.DictReader(f, delimiter=";"))
    assert tuple(header[: len(LARD_COLUMNS)]) == LARD_COLUMNS
    assert header[len(LARD_COLUMNS):] == [*(f"{c}_{n}_exact" for n in ("TR", "TL", "BL", "BR") for c in "xy"),
                                          "fov_deg", "reference"]
    for s, row in zip(samples, rows, strict=True):
        assert float(row["slant_distance"]) == pytest.approx(np.linalg.norm(s.position) / METRES_PER_NM, abs=1e-6)
        assert float(row["height_above_runway"]) == pytest.approx(s.position[2] * 3.28084, abs=1e-5)
        assert 80.0 < float(row["pitch"]) < 92.0  # stored as 90 + pitch
        assert float(row["fov_deg"]) == pytest.approx(60.0)
        assert row["reference"] == "VBLA at 43.6N 1.4E"
        assert row["vertical_path_angle"].count(".") == 1 and len(row["vertical_path_angle"].split(".")[1]) == 6
        for k, name in enumerate(("TR", "TL", "BL", "BR")):  # truncated towards zero, as the LARD labeller
            assert int(row[f"x_{name}"]) == int(s.corners_2d[k, 0])
            assert int(row[f"y_{name}"]) == int(s.corners_2d[k, 1])
        assert row["runway_in_cone"] == s.meta["runway_in_cone"]


def test_non_default_fov_round_trips_and_can_be_overridden(tmp_path, runway_db):
    samples = make_samples(runway_db, n=2, fov=40.0)
    csv_path = write_lard(tmp_path, samples, runway_db, image_format="jpg")
    back = read_lard(csv_path, tmp_path / "runways_db.json")
    np.testing.assert_allclose(back[0].K, samples[0].K, rtol=1e-9)
    assert back[0].id.endswith(".jpg") and back[0].image.shape == (H, W, 3)
    forced = read_lard(csv_path, tmp_path / "runways_db.json", fov_deg=60.0, width=320, height=240)
    assert forced[0].K[0, 2] == 160.0 and forced[0].width == 320


@pytest.mark.parametrize("mutate, match", [
    (lambda s, db: s.meta.pop("airport"), "meta must name 'airport'"),
    (lambda s, db: s.meta.update(airport="ZZZZ"), "airport 'ZZZZ' is not in runway_db"),
    (lambda s, db: s.meta.update(runway="18"), "runway '18' of .* is not in runway_db"),
    (lambda s, db: setattr(s, "corners_3d", s.corners_3d + 0.5), "corners_3d differ"),
    (lambda s, db: setattr(s, "K", s.K * np.array([[1, 0, 1], [0, 1, 1], [0, 0, 1]]) + np.diag([0, 5, 0])),
     "LARD camera"),
    (lambda s, db: setattr(s, "image", np.zeros((H, W), np.uint8)), "uint8 RGB"),
    (lambda s, db: s.corners_2d.__setitem__((0, 0), np.nan), "not finite"),
])
def test_writer_errors(tmp_path, runway_db, mutate, match):
    samples = make_samples(runway_db, n=2)
    mutate(samples[0], runway_db)
    with pytest.raises(ValueError, match=match):
        write_lard(tmp_path, samples, runway_db)


def test_writer_rejects_bad_format_and_duplicate_ids(tmp_path, runway_db):
    samples = make_samples(runway_db, n=2)
    with pytest.raises(ValueError, match="image_format"):
        write_lard(tmp_path, samples, runway_db, image_format="gif")
    samples[1].id = samples[0].id
    with pytest.raises(ValueError, match="duplicate sample id"):
        write_lard(tmp_path, samples, runway_db)


def test_writer_uses_meta_attitude_without_R(tmp_path, runway_db):
    s = make_samples(runway_db, n=1)[0]
    ref = read_lard(write_lard(tmp_path / "a", [s], runway_db), tmp_path / "a" / "runways_db.json")[0]
    s.R = None
    with pytest.raises(ValueError, match="no rotation R"):
        write_lard(tmp_path / "b", [s], runway_db)
    s.meta.update(yaw=ref.meta["yaw"], pitch=ref.meta["pitch"], roll=ref.meta["roll"])
    back = read_lard(write_lard(tmp_path / "c", [s], runway_db), tmp_path / "c" / "runways_db.json")[0]
    np.testing.assert_allclose(back.R, ref.R, atol=1e-9)
