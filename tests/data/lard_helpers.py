"""Synthetic samples and a runway DB for the LARD reader/writer tests (small images to stay fast)."""

from __future__ import annotations

import numpy as np

from vbl_robust.data.sample import Sample
from vbl_robust.geometry.camera import intrinsics, lard_rotation, project
from vbl_robust.geometry.geodesy import RunwayFrame, runway_db_entry

W, H = 160, 120


def make_runway_db():
    return {
        "VBLA": {
            "09": runway_db_entry(43.6, 1.4, 150.0, 92.3, 3000.0, 45.0, 1.5),
            "27L": runway_db_entry(43.6, 1.45, 151.0, 272.3, 2500.0, 40.0),
        },
        "VBLB": {"3R": runway_db_entry(-33.9, 151.17, 6.0, 33.0, 2000.0, 30.0)},
    }


def make_samples(runway_db, n=6, seed=0, fov=60.0):
    """``n`` samples on the approach of the DB runways, with random pixels and exact projected corners."""
    rng = np.random.default_rng(seed)
    keys = [(a, r) for a, rws in runway_db.items() for r in rws]
    K = intrinsics(W, H, fov)
    out = []
    for i in range(n):
        airport, runway = keys[i % len(keys)]
        corners = RunwayFrame.from_corners(runway_db[airport][runway]).corners_3d
        d = rng.uniform(600.0, 5000.0)
        C = np.array([-d, rng.uniform(-0.03, 0.03) * d, d * np.tan(np.radians(rng.uniform(2.0, 4.0)))])
        R = lard_rotation(100.0 + rng.uniform(-5, 5), 90.0 + rng.uniform(-5, 1), rng.uniform(-10, 10), 100.0)
        img = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
        s = Sample(id=f"scene_{i:03d}", K=K, corners_3d=corners, corners_2d=project(corners, R, C, K),
                   position=C, width=W, height=H, R=R,
                   meta={"airport": airport, "runway": runway, "runway_in_cone": "IN_ODD" if i % 2 else "OUT_OF_ODD"})
        s.image = img
        out.append(s)
    return out
