"""``vbl-robust check DATA``: a clean dataset exits 0; a missing, truncated, wrong-size or over-large image is named
and exits 1; a DATA that is no dataset exits 2 in one line."""

from __future__ import annotations

import csv
import json
import shutil
import struct
import zlib

import numpy as np
import pytest
from PIL import Image, ImageFile
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.scenes.export import write_dataset
from vbl_robust.scenes.sequences import write_sequences

runner = CliRunner()
SIZE = 96
WIDE = {"COLUMNS": "250"}  # rich tables at full width: no cell folded


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """A LARD V2 dataset of 3 JPEG images as `vbl-robust scenes` writes it (kept clean: tests copy it)."""
    root = tmp_path_factory.mktemp("clean")
    write_dataset(root, 3, seed=1, image_format="jpg", width=SIZE, height=SIZE)
    return root


@pytest.fixture
def data(clean, tmp_path):
    """A copy of the clean dataset to break, and its rows (as dicts, CSV order)."""
    root = tmp_path / "data"
    shutil.copytree(clean, root)
    return root, _rows(root)


def _rows(root):
    with open(root / "metadata.csv", newline="") as f:
        return list(csv.DictReader(f, delimiter=";"))


def _check(*args, env=WIDE):
    return runner.invoke(app, ["check", *map(str, args)], env=env)


def _summary(res):
    return next(line for line in res.output.splitlines() if " rows: " in line)


def test_a_clean_dataset_passes(data, tmp_path):
    root, rows = data
    out = tmp_path / "check.json"
    res = _check(root, "--json", out)
    assert res.exit_code == 0, res.output
    assert _summary(res).startswith("3 rows: 3 usable, 0 skipped, 0 with problems;")
    doc = json.loads(out.read_text())
    assert doc["summary"]["usable"] == 3 and doc["summary"]["unmeasured"] == 0
    assert [r["image"] for r in doc["rows"]] == [r["image"] for r in rows]
    for r in doc["rows"]:
        assert r["audit"] == "use" and r["image_ok"] and r["size"] == r["stated_size"] == [SIZE, SIZE]
        assert r["labels_exact"] is True and r["labels_max_px"] < 1e-3  # exact labels: the reprojection itself
    for r in rows:
        assert r["image"] in res.output
    assert "Traceback" not in res.output


def test_a_missing_image_is_named_and_exits_1(data, tmp_path):
    root, rows = data
    (root / rows[1]["image"]).unlink()
    out = tmp_path / "check.json"
    res = _check(root, "--json", out)
    assert res.exit_code == 1, res.output
    assert _summary(res).startswith("3 rows: 2 usable, 0 skipped, 1 with problems (1 image missing);")
    assert "1 would not be measured" in _summary(res) and "image file not found" in res.output
    bad = json.loads(out.read_text())["rows"][1]
    assert (bad["image"], bad["audit"], bad["image_kind"]) == (rows[1]["image"], "unmeasured", "missing")


def test_a_truncated_jpeg_exits_1(data):
    root, rows = data
    path = root / rows[0]["image"]
    noise = np.random.default_rng(0).integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
    Image.fromarray(noise).save(path, format="JPEG")  # a valid JPEG (of some size: its header stays whole) ...
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 3])  # ... cut to a third
    res = _check(root)
    assert res.exit_code == 1, res.output
    assert "(1 undecodable)" in _summary(res) and "cannot be decoded" in res.output and "truncated" in res.output


def test_a_wrong_size_image_exits_1(data):
    root, rows = data
    Image.fromarray(np.zeros((SIZE, SIZE + 8, 3), np.uint8)).save(root / rows[2]["image"], format="JPEG")
    res = _check(root)
    assert res.exit_code == 1, res.output
    assert "(1 another size than stated)" in _summary(res)
    assert f"the image is {SIZE + 8}x{SIZE} px, the CSV says {SIZE}x{SIZE}" in res.output


def test_an_over_large_header_exits_1_without_decoding(data, monkeypatch):
    root, rows = data

    def chunk(kind, payload):
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))

    header = chunk(b"IHDR", struct.pack(">IIBBBBB", 30000, 30000, 8, 2, 0, 0, 0))
    (root / rows[0]["image"]).write_bytes(b"\x89PNG\r\n\x1a\n" + header + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                                          + chunk(b"IEND", b""))
    decoded = []
    real_load = ImageFile.ImageFile.load
    monkeypatch.setattr(ImageFile.ImageFile, "load", lambda im: decoded.append(im.size) or real_load(im))
    res = _check(root)
    assert res.exit_code == 1, res.output
    assert "the header says 30000x30000 px, more than 8192 px a side (not decoded)" in res.output
    assert (30000, 30000) not in decoded and len(decoded) == 2  # the two sound images were decoded, not this one


@pytest.mark.parametrize("make, expected", [
    (lambda tmp: tmp / "nope", "no such directory"),
    (lambda tmp: (tmp / "file.csv").touch() or tmp / "file.csv", "not a directory"),
    (lambda tmp: (tmp / "empty").mkdir() or tmp / "empty", "no metadata CSV (*.csv) found"),
])
def test_a_bad_data_argument_exits_2_in_one_line(tmp_path, make, expected):
    path = make(tmp_path)
    res = _check(path)
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: ") and expected in lines[0], res.output


def test_a_malformed_csv_exits_2_in_one_line(data):
    root, _ = data
    with open(root / "metadata.csv", "a") as f:
        f.write("only;three;fields\n")
    res = _check(root)
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1 and "field(s)" in res.output


def test_a_row_for_another_runway_of_the_image_is_skipped(data, tmp_path):
    root, rows = data
    db_path = root / "runways_db.json"
    db = json.loads(db_path.read_text())
    airport, runway = rows[0]["airport"], rows[0]["runway"]
    e = next(v for k, v in db[airport].items() if k == runway)
    db[airport]["OPP"] = {"A": e["C"], "B": e["D"], "C": e["A"], "D": e["B"]}  # the same strip, flown the other way
    db_path.write_text(json.dumps(db))
    with open(root / "metadata.csv", "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]), delimiter=";", lineterminator="\n")
        w.writerow({**rows[0], "runway": "OPP", "uuid": "other"})
    out = tmp_path / "check.json"
    res = _check(root, "--json", out)
    assert res.exit_code == 0, res.output  # a skipped row is not a row the audit fails to measure
    assert _summary(res).startswith("4 rows: 3 usable, 1 skipped (not their image's target runway), 1 with problems "
                                    "(1 with labels off the camera)")
    skipped = json.loads(out.read_text())["rows"][3]
    assert skipped["audit"] == "skip" and f"the audit reads row 1, {airport} {runway}" in skipped["why"]
    assert skipped["labels_off"] and skipped["labels_max_px"] > 1.0  # its labels are row 1's, not this runway's


def test_problems_are_listed_first_and_all_rows_on_request(tmp_path):
    root = tmp_path / "many"
    write_dataset(root, 23, seed=2, width=48, height=48)
    rows = _rows(root)
    (root / rows[-1]["image"]).unlink()
    res = _check(root)
    assert res.exit_code == 1
    table = res.output.split("labels Δ:")[0]
    assert table.index(rows[-1]["image"]) < table.index(rows[0]["image"])  # the problem first
    assert rows[20]["image"] not in table and "3 more row(s) not shown: --all prints them" in res.output
    every = _check(root, "--all")
    assert all(r["image"] in every.output for r in rows) and "not shown" not in every.output


def test_quiet_prints_the_summary_line_only(data):
    root, _ = data
    res = _check(root, "--quiet")
    assert res.exit_code == 0 and res.output.strip().splitlines() == [_summary(res)]


def test_sequences_a_frame_missing_leaves_its_sequence_unmeasured(tmp_path):
    root = tmp_path / "seq"
    write_sequences(root, 2, 3, 5.0, seed=3, width=48, height=48)
    rows = _rows(root)
    (root / rows[1]["image"]).unlink()
    out = tmp_path / "check.json"
    res = _check(root, "--sequences", "--json", out)
    assert res.exit_code == 1, res.output
    doc = json.loads(out.read_text())
    broken = rows[1]["sequence_id"]
    for r in doc["rows"]:
        assert (r["audit"] == "unmeasured") == (r["sequence"] == broken), r
    assert doc["summary"]["sequences"] == 2 and doc["summary"]["sequences_unmeasured"] == 1
    assert "2 sequences, 1 not measured" in _summary(res)
    # without --sequences the other frames are usable images
    assert "2 would not be measured" not in _summary(_check(root)) and _check(root).exit_code == 1


def test_check_is_listed_in_the_help():
    res = runner.invoke(app, ["--help"])
    assert res.exit_code == 0 and "check" in res.output
