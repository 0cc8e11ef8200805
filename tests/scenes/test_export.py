import numpy as np

from vbl_robust.data.lard_read import read_lard
from vbl_robust.scenes.export import write_dataset
from vbl_robust.scenes.generate import generate


def test_write_dataset_round_trips_through_the_lard_reader(tmp_path):
    csv = write_dataset(tmp_path, 3, seed=6, width=128, height=128)
    text = csv.read_text()
    assert text.splitlines()[0].count(";") > 20 and "seed=6" in text
    back = read_lard(csv, tmp_path / "runways_db.json", fov_deg=60.0)
    ref = generate(3, seed=6, width=128, height=128)
    assert len(back) == 3
    for b, r in zip(back, ref, strict=True):
        np.testing.assert_allclose(b.position, r.position, atol=0.05)
        np.testing.assert_allclose(b.corners_3d, r.corners_3d, atol=0.01)
        np.testing.assert_array_equal(b.image, r.image)  # PNG is lossless
        # LARD stores truncated integer corners
        assert np.all(np.abs(b.corners_2d - r.corners_2d) <= 1.0 + 1e-6)
