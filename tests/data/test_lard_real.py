"""A published LARD V2 row (tests/fixtures/lard/README.md): our geometry reproduces its truncated labels.

Measured: projection − label = u 0.10…0.89 px, v −0.42…0.51 px (a perfect model gives [0, 1) because the
labels are integer-truncated), i.e. every corner within 0.42 px of its truncation cell.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vbl_robust.data.lard_read import read_lard
from vbl_robust.geometry.camera import project

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "lard"


@pytest.fixture(scope="module")
def sample():
    (s,) = read_lard(FIXTURES / "cyeg_row.csv", FIXTURES / "runways_db_cyeg.json")
    return s


def test_real_row_reprojects_onto_its_labels(sample):
    uv = project(sample.corners_3d, sample.R, sample.position, sample.K)
    residual = uv - sample.corners_2d
    # truncated labels: true − label ∈ [0, 1); allow 0.5 px of model/DB error around that interval
    assert np.all(residual >= -0.5) and np.all(residual < 1.5), residual
    assert np.max(np.abs(residual - 0.5)) < 1.0
    assert np.array_equal(np.trunc(uv[:3]), sample.corners_2d[:3])  # TR, TL, BL land in their label's cell


def test_real_row_geometry_is_a_plausible_approach(sample):
    assert sample.id == "CYEG-20_000.jpg" and sample.meta["runway_db_key"] == "20"
    assert sample.meta["yaw"] == -149.64 and sample.meta["pitch"] == 87.63
    x, y, z = sample.position
    assert -5800 < x < -5700 and -110 < y < -90 and 290 < z < 300  # ≈ 3.1 NM out, ~1° right, ~3° glide
    d = sample.meta["derived"]
    assert d["slant_distance"] == pytest.approx(3.11, abs=0.01)
    assert 2.5 < d["vertical_path_angle"] < 3.5 and 0.8 < d["lateral_path_angle"] < 1.3  # right of centreline: > 0
    assert sample.meta["runway_heading_deg"] == pytest.approx(214.92, abs=0.01)
    assert sample.meta["lard_check"] == {}


def test_yaw_reference_matters(sample):
    """Referencing yaw to the sphere azimuth instead of the WGS84 heading shifts u by ≈ 1 px (docstring table)."""
    from vbl_robust.geometry.camera import lard_rotation

    m = sample.meta
    R_sphere = lard_rotation(m["yaw"], m["pitch"], m["roll"], m["runway_azimuth_deg"])
    du = project(sample.corners_3d, R_sphere, sample.position, sample.K)[:, 0] - \
        project(sample.corners_3d, sample.R, sample.position, sample.K)[:, 0]
    assert np.all(np.abs(du + 1.0) < 0.1)
