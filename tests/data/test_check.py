"""The pre-run checks of a dataset (vbl_robust.data.check): images read as a run reads them, at their stated size,
refused before decoding when the header is too large; labels against the reprojected corners."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
from lard_helpers import H, W, make_runway_db, make_samples
from PIL import Image, ImageFile

from vbl_robust.constants import MAX_IMAGE_SIDE
from vbl_robust.data.check import (
    CAMERA_CONVENTION,
    MAX_IMAGE_FILE_BYTES,
    check_image,
    check_images,
    check_labels,
    describe_problems,
    first_problem,
    image_digests,
)
from vbl_robust.data.lard_read import read_lard
from vbl_robust.data.lard_write import write_lard
from vbl_robust.data.sequence import ApproachSequence
from vbl_robust.digest import file_sha256


@pytest.fixture
def rows(tmp_path):
    """A written dataset (JPEG images) read back: (root, samples)."""
    db = make_runway_db()
    root = tmp_path / "ds"
    csv_path = write_lard(root, make_samples(db, n=4), db, image_format="jpg")
    return root, read_lard(csv_path, root / "runways_db.json")


def png_header(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` (a few compressed bytes of data: PIL opens it lazily)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    body = chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")
    return b"\x89PNG\r\n\x1a\n" + body


def test_a_clean_dataset_passes_with_sizes_and_labels(rows):
    root, samples = rows
    checks = check_images(samples, root=root)
    assert [c.sample_id for c in checks] == [s.id for s in samples]
    assert all(c.ok and c.problem == "" and c.size == (W, H) for c in checks)
    assert [c.path for c in checks] == [s.id for s in samples]  # relative to the root, as the CSV writes it
    assert first_problem(samples) is None and describe_problems(checks) is None
    for s in samples:
        labels = check_labels(s)
        assert labels.ok and labels.exact is True and labels.behind == 0 and labels.max_px < 1e-3


def test_in_memory_samples_pass_without_a_file():
    samples = make_samples(make_runway_db(), n=2)
    checks = check_images(samples)
    assert all(c.ok and c.path is None and c.size is None for c in checks)
    assert check_labels(samples[0]).max_px < 1e-9 and check_labels(samples[0]).exact is None


def test_a_missing_image_is_named_relative_to_the_root(rows):
    root, samples = rows
    samples[2].image_path.unlink()
    checks = check_images(samples, root=root)
    bad = [c for c in checks if not c.ok]
    assert [(c.path, c.problem, c.kind) for c in bad] == [(samples[2].id, "image file not found", "missing")]
    line = first_problem(samples)
    assert line == f"1 of 4 image(s) cannot be used: {samples[2].id}: image file not found"
    assert str(root) not in line and "\n" not in line


def test_a_truncated_jpeg_is_refused(rows):
    root, samples = rows
    data = samples[1].image_path.read_bytes()
    samples[1].image_path.write_bytes(data[: len(data) // 3])
    check = check_images(samples, root=root)[1]
    # the header is whole: decoding finds it
    assert not check.ok and check.size == (W, H) and check.kind == "undecodable"
    assert check.problem.startswith("cannot be decoded") and "truncated" in check.problem


def test_a_truncated_jpeg_is_refused_even_when_pil_was_set_lenient(rows, monkeypatch):
    root, samples = rows
    data = samples[0].image_path.read_bytes()
    samples[0].image_path.write_bytes(data[: len(data) // 3])
    monkeypatch.setattr(ImageFile, "LOAD_TRUNCATED_IMAGES", True)
    max_pixels = Image.MAX_IMAGE_PIXELS
    assert not check_images(samples)[0].ok
    assert ImageFile.LOAD_TRUNCATED_IMAGES is True and Image.MAX_IMAGE_PIXELS == max_pixels  # restored


def test_a_wrong_size_image_is_refused_with_both_sizes(rows):
    root, samples = rows
    Image.fromarray(np.zeros((H + 10, W, 3), np.uint8)).save(samples[3].image_path, format="JPEG")
    check = check_images(samples, root=root)[3]
    assert not check.ok and check.size == (W, H + 10) and check.kind == "size"
    # the line says what the camera model assumes of that size (horizontal FOV, square pixels, centred)
    assert check.problem == f"the image is {W}x{H + 10} px, the CSV says {W}x{H} {CAMERA_CONVENTION}"
    assert "horizontal field of view" in CAMERA_CONVENTION and "square pixels" in CAMERA_CONVENTION


def test_an_over_large_header_is_refused_without_decoding(rows, monkeypatch):
    root, samples = rows
    samples[0].image_path.write_bytes(png_header(30000, 30000))

    def no_decode(self):
        raise AssertionError("decoded")

    monkeypatch.setattr(ImageFile.ImageFile, "load", no_decode)
    monkeypatch.setattr(Image.Image, "load", no_decode)
    check = check_images(samples[:1], root=root)[0]
    assert not check.ok and check.size == (30000, 30000) and check.kind == "too_large"
    assert check.problem == f"the header says 30000x30000 px, more than {MAX_IMAGE_SIDE} px a side (not decoded)"


def test_a_file_larger_than_any_accepted_image_is_refused_unread(rows, monkeypatch):
    root, samples = rows
    with open(samples[0].image_path, "r+b") as fh:  # a sparse file: the header of an image, then a hole
        fh.truncate(MAX_IMAGE_FILE_BYTES + 1)

    def no_open(*args, **kwargs):
        raise AssertionError("opened")

    monkeypatch.setattr(Image, "open", no_open)
    check = check_images(samples[:1], root=root)[0]
    assert not check.ok and check.size is None and "MiB, more than any image" in check.problem


def test_an_exif_orientation_is_refused(rows):
    _, samples = rows
    exif = Image.Exif()
    exif[0x0112] = 6  # OpenCV's imread would turn the image by 90°
    Image.fromarray(np.zeros((H, W, 3), np.uint8)).save(samples[0].image_path, format="JPEG", exif=exif)
    check = check_images(samples)[0]
    assert not check.ok and check.problem.startswith("EXIF orientation 6")


def test_not_an_image_and_an_empty_file_are_refused(rows):
    _, samples = rows
    samples[0].image_path.write_text("not an image")
    samples[1].image_path.write_bytes(b"")
    checks = check_images(samples)
    assert checks[0].problem == "not an image file (neither PIL nor OpenCV knows its format)"
    assert checks[1].problem == "the image file is empty"


def test_a_format_only_opencv_reads_is_checked_by_opencv(rows):
    import cv2

    _, samples = rows
    s = samples[0]
    s.image_path = s.image_path.with_suffix(".hdr")  # Radiance HDR: PIL cannot identify it
    cv2.imwrite(str(s.image_path), np.ones((H, W, 3), np.float32))
    assert check_image(s).ok
    cv2.imwrite(str(s.image_path), np.ones((H, W + 1, 3), np.float32))
    assert check_image(s).problem == f"the image is {W + 1}x{H} px, the CSV says {W}x{H} {CAMERA_CONVENTION}"


def test_an_image_outside_the_root_is_refused(rows, tmp_path):
    root, samples = rows
    outside = tmp_path / "elsewhere.jpg"
    outside.write_bytes(samples[0].image_path.read_bytes())
    samples[0].image_path.unlink()
    samples[0].image_path.symlink_to(outside)
    assert check_images(samples)[0].ok  # without a root: the reader's confinement only
    check = check_images(samples, root=root)[0]
    assert not check.ok and check.problem.startswith("the image file lies outside the dataset root")


def test_digests_are_the_files_sha256_and_spare_the_store_a_second_read(rows, tmp_path, monkeypatch):
    import vbl_robust.digest
    from vbl_robust.store.core import ResultStore

    root, samples = rows
    checks = check_images(samples, root=root, sha256=True)
    digests = image_digests(checks)
    assert digests == {s.id: file_sha256(s.image_path) for s in samples}
    assert all(c.sha256 is None for c in check_images(samples))

    def no_hash(path, chunk=1 << 20):
        raise AssertionError(f"hashed {path} again")

    monkeypatch.setattr(vbl_robust.digest, "file_sha256", no_hash)
    with ResultStore(tmp_path / "results.sqlite") as store:
        store.check_contents(samples, digests=digests)
        assert {r[0]: r[4] for r in store.contents()} == digests


def test_a_file_shared_by_samples_is_checked_once_per_stated_size(rows):
    _, samples = rows
    samples[1].image_path = samples[0].image_path
    samples[2].image_path = samples[0].image_path
    samples[2].width = W + 1
    done = []
    checks = check_images(samples, progress=lambda i, n: done.append((i, n)))
    assert [c.sample_id for c in checks] == [s.id for s in samples]
    assert checks[0].ok and checks[1].ok and not checks[2].ok
    assert done[-1] == (4, 4) and len(done) == 3  # three distinct (file, size) pairs


def test_sequences_count_as_their_frames(rows):
    _, samples = rows
    seqs = [ApproachSequence("A", samples[:2], [0.0, 0.1], [0, 1]),
            ApproachSequence("B", samples[2:], [0.0, 0.1], [0, 1])]
    samples[3].image_path.unlink()
    checks = check_images(seqs)
    assert [c.sample_id for c in checks] == [s.id for s in samples]
    assert [c.ok for c in checks] == [True, True, True, False]


def test_labels_off_the_camera_are_measured_and_flagged_by_the_reader(tmp_path):
    import csv

    db = make_runway_db()
    root = tmp_path / "ds"
    csv_path = write_lard(root, make_samples(db, n=2), db)
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f, delimiter=";")
        header, table = list(reader.fieldnames), list(reader)
    table[0]["x_TL_exact"] = f"{float(table[0]['x_TL_exact']) + 20.0:.6f}"
    table[0]["x_TL"] = str(int(float(table[0]["x_TL_exact"])))
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=header, delimiter=";", lineterminator="\n")
        w.writeheader()
        w.writerows(table)
    moved, clean = (check_labels(s) for s in read_lard(csv_path, root / "runways_db.json"))
    assert moved.max_px == pytest.approx(20.0, abs=1e-3) and "x_TL_exact" in moved.off and not moved.ok
    assert clean.ok and clean.max_px < 1e-3


def test_a_bad_thread_count_is_refused(rows):
    with pytest.raises(ValueError, match="threads must be an integer >= 1, got 0"):
        check_images(rows[1], threads=0)
