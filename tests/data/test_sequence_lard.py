"""Approach sequences in LARD V2 format: the sequence columns round trip, and the reader's grouping rules."""

import csv
import dataclasses

import numpy as np
import pytest

from vbl_robust.data.lard import SEQUENCE_COLUMNS
from vbl_robust.data.lard_read import read_lard
from vbl_robust.data.lard_write import write_lard
from vbl_robust.data.sequence import ApproachSequence, group_sequences, read_lard_sequences
from vbl_robust.scenes.export import write_dataset
from vbl_robust.scenes.generate import generate
from vbl_robust.scenes.sequences import generate_sequences, write_sequences

SMALL = {"width": 96, "height": 96}


def _rewrite_without(csv_path, drop, out_path):
    rows = list(csv.DictReader(open(csv_path, encoding="utf-8"), delimiter=";"))
    fields = [f for f in rows[0] if f not in drop]
    with open(out_path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=fields, delimiter=";", extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return out_path


def test_sequence_columns_round_trip(tmp_path):
    csv_path = write_sequences(tmp_path, 2, 4, 5.0, seed=2, **SMALL)
    header = csv_path.read_text().splitlines()[0].split(";")
    assert header[-3:] == list(SEQUENCE_COLUMNS)
    back = read_lard_sequences(csv_path, tmp_path / "runways_db.json")
    ref = generate_sequences(2, 4, 5.0, seed=2, **SMALL)
    assert [q.id for q in back] == [q.id for q in ref]
    for b, r in zip(back, ref, strict=True):
        assert b.meta["grouped_by"] == "columns" and b.meta["time_source"] == "time_s" and b.meta["gaps"] == []
        np.testing.assert_array_equal(b.frame_index, r.frame_index)
        np.testing.assert_allclose(b.times, r.times, atol=1e-6)
        np.testing.assert_allclose(b.distances_m, r.distances_m, atol=0.05)
        for s, t in zip(b, r, strict=True):
            assert s.id == f"images/{t.id}.png"
            np.testing.assert_allclose(s.position, t.position, atol=0.05)
            np.testing.assert_allclose(s.corners_2d, t.corners_2d, atol=1e-3)
        np.testing.assert_array_equal(b[1].image, r[1].image)


def test_single_image_datasets_have_no_sequence_columns(tmp_path):
    csv_path = write_dataset(tmp_path, 2, seed=0, **SMALL)
    assert not set(SEQUENCE_COLUMNS) & set(csv_path.read_text().splitlines()[0].split(";"))


def test_grouping_by_image_names_when_the_columns_are_absent(tmp_path):
    csv_path = write_sequences(tmp_path, 2, 3, 2.0, seed=1, **SMALL)
    bare = _rewrite_without(csv_path, SEQUENCE_COLUMNS, tmp_path / "bare.csv")
    seqs = read_lard_sequences(bare, tmp_path / "runways_db.json")
    assert [q.id for q in seqs] == ["images/synth_q1_0000", "images/synth_q1_0001"]
    assert all(q.meta["grouped_by"] == "names" and q.meta["time_source"] == "unknown" for q in seqs)
    assert np.isnan(seqs[0].times).all()
    timed = read_lard_sequences(bare, tmp_path / "runways_db.json", rate_hz=4.0)
    np.testing.assert_allclose(timed[1].times, [0.0, 0.25, 0.5])
    assert timed[0].meta["time_source"] == "rate_hz"


def test_folder_per_sequence_and_frame_order():
    base = generate(3, seed=0, **SMALL)
    names = ["approach7/0002.png", "approach7/0000.png", "other/B_0005.png"]
    samples = [dataclasses.replace(s, id=n, meta={}) for s, n in zip(base, names, strict=True)]
    seqs = group_sequences(samples)
    assert [(q.id, q.frame_index.tolist()) for q in seqs] == [("approach7", [0, 2]), ("other/B", [5])]
    assert seqs[0].meta["gaps"] == [1]
    assert seqs[0].samples[0] is samples[1]


def test_frames_grouped_by_name_must_show_one_runway():
    """A file-name prefix shared by approaches to two runways is not one sequence: refused, naming both."""
    base = generate(2, seed=0, **SMALL)
    metas = [{"airport": "LFPO", "runway": "06"}, {"airport": "EGLL", "runway": "27L"}]
    samples = [dataclasses.replace(s, id=f"approach/{i:04d}.png", meta=m)
               for i, (s, m) in enumerate(zip(base, metas, strict=True))]
    with pytest.raises(ValueError, match=r"sequence 'approach' \(grouped by image names\) mixes runways EGLL/27L, "
                                         r"LFPO/06"):
        group_sequences(samples)
    same = [dataclasses.replace(s, meta=metas[0]) for s in samples]
    assert [len(q.samples) for q in group_sequences(same)] == [2]


def test_times_from_time_to_landing():
    base = generate(3, seed=0, **SMALL)
    samples = [dataclasses.replace(s, id=f"CYEG-20_{i:03d}.jpg", meta={"time_to_landing": str(30.0 - 0.5 * i)})
               for i, s in enumerate(base)]
    (q,) = group_sequences(samples)
    assert q.id == "CYEG-20" and q.meta["time_source"] == "time_to_landing"
    np.testing.assert_allclose(q.times, [0.0, 0.5, 1.0])


def _rows(n=3, meta_of=None):
    base = generate(n, seed=0, **SMALL)
    out = []
    for i, s in enumerate(base):
        meta = {"csv": "data.csv", "row": i + 1, "sequence_id": "A", "frame_index": str(i), "time_s": str(0.1 * i)}
        meta.update((meta_of or {}).get(i, {}))
        out.append(dataclasses.replace(s, id=f"img{i}.png", meta=meta))
    return out


@pytest.mark.parametrize("samples, message", [
    (lambda: _rows(meta_of={1: {"sequence_id": ""}}), r"data.csv: row 2 \(image 'img1.png'\): field 'sequence_id' is empty"),
    (lambda: _rows(meta_of={2: {"frame_index": "x"}}), r"row 3 .*field 'frame_index' = 'x' is not an integer >= 0"),
    (lambda: _rows(meta_of={2: {"frame_index": "0"}}), r"row 3 .*sequence 'A' frame 0 appears twice"),
    (lambda: _rows(meta_of={2: {"time_s": "0.05"}}), r"row 3 .*frame 2 has time 0.05 s \(from time_s\), not after"),
    (lambda: _rows(meta_of={1: {"time_s": "soon"}}), r"row 2 .*field 'time_s' = 'soon' is not a number"),
    (lambda: [dataclasses.replace(s, id="runway.png", meta={}) for s in generate(1, seed=0, **SMALL)],
     r"sample 'runway.png': image name 'runway.png' does not name a sequence frame"),
])
def test_grouping_errors_name_the_row_and_field(samples, message):
    with pytest.raises(ValueError, match=message):
        group_sequences(samples())


def test_rate_and_sequence_checks():
    with pytest.raises(ValueError, match="rate_hz must be a finite number > 0"):
        group_sequences(_rows(), rate_hz=0.0)
    s = _rows(2)
    with pytest.raises(ValueError, match="strictly increasing"):
        ApproachSequence("A", s, [0.0, 0.0], [0, 1])
    with pytest.raises(ValueError, match="no frames"):
        ApproachSequence("A", [], [], [])


def test_writer_refuses_sequence_fields_on_some_samples_only(tmp_path):
    q = generate_sequences(1, 2, 1.0, seed=0, **SMALL)[0]
    from vbl_robust.geometry.geodesy import runway_db_entry
    from vbl_robust.scenes.airports import make_airport

    a = make_airport(0, 0)
    db = {a.icao: {a.runway: runway_db_entry(a.ltp_lat, a.ltp_lon, a.ltp_alt, a.azimuth_deg, a.length_m, a.width_m)}}
    q[1].meta = {k: v for k, v in q[1].meta.items() if k != "sequence_id"}
    with pytest.raises(ValueError, match="has no meta 'sequence_id' but image 'images/synth_q0_0000_0000.png' has one"):
        write_lard(tmp_path, q.samples, db)
    q[1].meta["sequence_id"], q[1].meta["frame_index"] = q.id, 1.5
    with pytest.raises(ValueError, match="meta 'frame_index' = 1.5 is not an integer >= 0"):
        write_lard(tmp_path, q.samples, db)
    # and a sequence dataset reads back as plain samples too
    q[1].meta["frame_index"] = 1
    csv_path = write_lard(tmp_path, q.samples, db)
    rows = read_lard(csv_path, tmp_path / "runways_db.json")
    assert [r.meta["frame_index"] for r in rows] == ["0", "1"]
