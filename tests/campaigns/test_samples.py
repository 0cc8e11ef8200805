import pytest

from vbl_robust.campaigns.samples import find_lard_files, load_samples


def test_load_synthetic_samples_is_seeded():
    a, src = load_samples(2, 4, width=96, height=96)
    b, _ = load_samples(2, 4, width=96, height=96)
    assert [s.id for s in a] == [s.id for s in b] and (a[0].position == b[0].position).all()
    assert src == {"kind": "synthetic", "n": 2, "seed": 4, "width": 96, "height": 96}
    with pytest.raises(ValueError, match="number of images"):
        load_samples(0, 0)


def test_lard_directory_round_trip_and_random_subset(tmp_path):
    from vbl_robust.scenes.export import write_dataset

    write_dataset(tmp_path / "ds", 4, seed=2, width=96, height=96)
    samples, src = load_samples(2, 0, lard=tmp_path / "ds")
    assert len(samples) == 2 and src["kind"] == "lard" and src["rows"] == 4 and len(src["csv_sha256"]) == 64
    again, _ = load_samples(2, 0, lard=tmp_path / "ds")
    assert [s.id for s in again] == [s.id for s in samples]
    everything, _ = load_samples(4, 0, lard=tmp_path / "ds")
    assert len(everything) == 4
    with pytest.raises(ValueError, match="10 images asked for, the dataset has 4 usable rows"):
        load_samples(10, 0, lard=tmp_path / "ds")
    assert samples[0].image.shape == (96, 96, 3)


def test_find_lard_files_errors_name_the_problem(tmp_path):
    with pytest.raises(FileNotFoundError, match="not a directory"):
        find_lard_files(tmp_path / "nope")
    (tmp_path / "a.csv").write_text("x")
    with pytest.raises(FileNotFoundError, match="runway database JSON"):
        find_lard_files(tmp_path)
    (tmp_path / "db.json").write_text("{}")
    assert find_lard_files(tmp_path) == (tmp_path / "a.csv", tmp_path / "db.json")
    (tmp_path / "b.csv").write_text("x")
    with pytest.raises(ValueError, match="several metadata CSV files"):
        find_lard_files(tmp_path)
