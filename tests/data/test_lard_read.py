"""read_lard: options, target runway, derived-column cross-check and one-line errors naming file/row/field."""

from __future__ import annotations

import csv
import json
import logging
import os

import numpy as np
import pytest
from lard_helpers import make_runway_db, make_samples

from vbl_robust.data.lard import normalize_runway
from vbl_robust.data.lard_read import read_lard
from vbl_robust.data.lard_write import write_lard


@pytest.fixture
def dataset(tmp_path):
    """A written dataset: (csv path, db path, samples)."""
    db = make_runway_db()
    samples = make_samples(db, n=4)
    csv_path = write_lard(tmp_path / "ds", samples, db)
    return csv_path, tmp_path / "ds" / "runways_db.json", samples


def rewrite(csv_path, edit):
    """Apply ``edit(header, rows)`` to a CSV in place (rows are dicts)."""
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f, delimiter=";")
        header, rows = list(reader.fieldnames), list(reader)
    header, rows = edit(header, rows) or (header, rows)
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header, delimiter=";", lineterminator="\n", extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)


def set_field(field, value, row=0):
    def edit(header, rows):
        rows[row][field] = value
    return edit


def drop_columns(*names):
    def edit(header, rows):
        return [h for h in header if h not in names], rows
    return edit


def test_runway_keys_are_normalised():
    assert [normalize_runway(k) for k in ("02", "2", " 03r", "36", "09L", "27")] == ["2", "2", "3R", "36", "9L", "27"]


def test_runway_key_padding_in_csv_does_not_matter(dataset):
    csv_path, db_path, samples = dataset
    rewrite(csv_path, set_field("runway", "9"))  # DB stores "09"
    rewrite(csv_path, set_field("runway", "027l", row=1))  # DB stores "27L"
    back = read_lard(csv_path, db_path)
    assert back[0].meta["runway_db_key"] == "09" and back[1].meta["runway_db_key"] == "27L"


def test_geometry_needs_no_image_and_missing_image_fails_on_access(dataset):
    csv_path, db_path, _ = dataset
    os.remove(csv_path.parent / "images" / "scene_000.png")
    s = read_lard(csv_path, db_path)[0]
    assert s.corners_3d.shape == (4, 3)
    with pytest.raises(FileNotFoundError, match=r"^images/scene_000\.png: image file not found$"):  # no absolute path
        _ = s.image


def test_unreadable_image_fails_on_access(dataset):
    csv_path, db_path, _ = dataset
    (csv_path.parent / "images" / "scene_001.png").write_bytes(b"not a png")
    s = read_lard(csv_path, db_path)[1]
    with pytest.raises(ValueError, match=r"^images/scene_001\.png: unreadable image"):
        _ = s.image


def test_only_required_columns_and_derived_computed(dataset):
    csv_path, db_path, samples = dataset
    rewrite(csv_path, drop_columns("uuid", "type", "slant_distance", "along_track_distance", "height_above_runway",
                                   "lateral_path_angle", "vertical_path_angle", "runway_in_cone", "fov_deg",
                                   "x_TR_exact"))
    back = read_lard(csv_path, db_path)
    for s, r in zip(samples, back, strict=True):
        assert r.meta["corners_exact"] is False  # one exact column missing → the truncated labels are used
        np.testing.assert_array_equal(r.corners_2d, np.trunc(s.corners_2d))
        assert r.meta["derived"]["slant_distance"] == pytest.approx(s.slant_distance_m / 1852.0)
        assert r.meta["lard_check"] == {}


def test_derived_disagreement_is_flagged_and_logged(dataset, caplog):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, set_field("slant_distance", "9.5", row=2))
    with caplog.at_level(logging.WARNING, logger="vbl_robust.data.lard_read"):
        back = read_lard(csv_path, db_path)
    assert set(back[2].meta["lard_check"]) == {"slant_distance"}
    assert back[2].meta["lard_check"]["slant_distance"][0] == 9.5
    assert all(not s.meta["lard_check"] for i, s in enumerate(back) if i != 2)
    assert "1 row(s) have derived columns or corner labels disagreeing" in caplog.text and "row 3" in caplog.text


def test_filters(dataset):
    csv_path, db_path, samples = dataset
    odd = read_lard(csv_path, db_path, in_odd_only=True)
    assert [s.id for s in odd] == [f"images/{s.id}.png" for s in samples if s.meta["runway_in_cone"] == "IN_ODD"]
    inside = read_lard(csv_path, db_path, corners_in_image=True)
    assert [s.id for s in inside] == [f"images/{s.id}.png" for s in samples if s.corners_in_image()]
    rewrite(csv_path, drop_columns("runway_in_cone"))
    with pytest.raises(ValueError, match="in_odd_only needs the column 'runway_in_cone'"):
        read_lard(csv_path, db_path, in_odd_only=True)


def test_target_runway_selection(tmp_path):
    db = make_runway_db()
    s = make_samples(db, n=1)[0]  # VBLA 09
    csv_path = write_lard(tmp_path, [s], db)

    def duplicate_as(runway, scenario, image=None):
        def edit(header, rows):
            extra = dict(rows[0], runway=runway)
            rows[0]["scenario"] = extra["scenario"] = scenario
            if image:
                rows[0]["image"] = extra["image"] = image
            rows.append(extra)
        return edit

    rewrite(csv_path, duplicate_as("27L", "VBLA-27L"))  # the scenario names the second row's runway
    back = read_lard(csv_path, tmp_path / "runways_db.json")
    assert len(back) == 1 and back[0].meta["runway"] == "27L"
    both = read_lard(csv_path, tmp_path / "runways_db.json", target_runway_only=False)
    assert [r.id for r in both] == ["images/scene_000.png#09", "images/scene_000.png#27L"]

    csv_path = write_lard(tmp_path / "b", [s], db)
    os.rename(tmp_path / "b" / "images" / "scene_000.png", tmp_path / "b" / "images" / "VBLA-09_000.png")
    rewrite(csv_path, duplicate_as("27L", "approach", image="images/VBLA-09_000.png"))  # named by the image
    assert read_lard(csv_path, tmp_path / "b" / "runways_db.json")[0].meta["runway"] == "09"

    csv_path = write_lard(tmp_path / "c", [s], db)
    rewrite(csv_path, duplicate_as("27L", "no target here"))  # fallback: lined-up runway (smallest lateral angle)
    assert read_lard(csv_path, tmp_path / "c" / "runways_db.json")[0].meta["runway"] == "09"


BAD_VALUES = [
    ("lat_cam", "north"), ("alt_cam", "nan"), ("yaw", ""), ("x_BL_exact", "inf"), ("width", "1024.5"),
]


@pytest.mark.parametrize("field, value", BAD_VALUES)
def test_bad_values_name_file_row_field_value(dataset, field, value):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, set_field(field, value, row=1))
    with pytest.raises(ValueError) as err:
        read_lard(csv_path, db_path)
    msg = str(err.value)
    assert "\n" not in msg
    assert str(csv_path) in msg and "row 2" in msg and "images/scene_001.png" in msg
    assert f"'{field}'" in msg and repr(value) in msg


def test_missing_column(dataset):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, drop_columns("alt_cam", "y_BR"))
    with pytest.raises(ValueError, match=r"metadata\.csv: missing column\(s\) alt_cam, y_BR"):
        read_lard(csv_path, db_path)


@pytest.mark.parametrize("field, value, match", [
    ("airport", "ZZZZ", r"row 1 .*field 'airport' = 'ZZZZ' is not in the runway DB"),
    ("runway", "18", r"row 1 .*field 'runway' = '18' is not a runway of VBLA .*has 09, 27L"),
])
def test_unknown_airport_or_runway(dataset, field, value, match):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, set_field(field, value))
    with pytest.raises(ValueError, match=match):
        read_lard(csv_path, db_path)


def test_bad_runway_db(dataset, tmp_path):
    csv_path, db_path, _ = dataset
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match=r"bad\.json: malformed runway DB JSON"):
        read_lard(csv_path, bad)
    db = json.loads(db_path.read_text())
    del db["VBLA"]["09"]["C"]
    bad.write_text(json.dumps(db))
    with pytest.raises(ValueError, match=r"bad\.json: airport 'VBLA' runway '09': expected corners A, B, C, D"):
        read_lard(csv_path, bad)
    db = json.loads(db_path.read_text())
    db["VBLA"]["09"]["C"]["coordinate"]["latitude"] = "x"
    bad.write_text(json.dumps(db))
    with pytest.raises(ValueError, match=r"bad\.json: airport 'VBLA' runway '09' corner 'C': field 'coordinate\.latitude' = 'x' is not a number"):
        read_lard(csv_path, bad)
    with pytest.raises(FileNotFoundError, match="nope.json: runway DB file not found"):
        read_lard(csv_path, tmp_path / "nope.json")
    with pytest.raises(FileNotFoundError, match="metadata CSV not found"):
        read_lard(tmp_path / "nope.csv", db_path)


@pytest.mark.parametrize("image", ["../outside.png", "images/../../outside.png", "/etc/passwd", "C:\\x.png"])
def test_image_paths_escaping_the_root(dataset, image):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, set_field("image", image))
    with pytest.raises(ValueError, match=r"row 1 .*field 'image': path .* (absolute|contains '\.\.')"):
        read_lard(csv_path, db_path)


def test_symlink_escaping_the_root(dataset, tmp_path):
    csv_path, db_path, _ = dataset
    outside = tmp_path / "outside"
    outside.mkdir()
    (csv_path.parent / "images" / "link").symlink_to(outside, target_is_directory=True)
    rewrite(csv_path, set_field("image", "images/link/x.png"))
    with pytest.raises(ValueError, match=r"row 1 .*field 'image': path 'images/link/x\.png' resolves to .*outside"):
        read_lard(csv_path, db_path)


def test_root_option(dataset):
    csv_path, db_path, _ = dataset
    rewrite(csv_path, set_field("image", "ds/images/scene_000.png"))
    s = read_lard(csv_path, db_path, root=csv_path.parent.parent)[0]
    assert s.id == "ds/images/scene_000.png" and s.image.shape[2] == 3
