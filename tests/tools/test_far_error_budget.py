"""``tools/far_error_budget.py``'s reading of the painted runway surfaces (the per-airport columns of its table)."""

from __future__ import annotations

import numpy as np


def test_surfaces_find_every_runway_and_the_generators_shoulders(script):
    from vbl_robust.scenes.airports import make_airports

    out = script("tools/far_error_budget.py").surfaces(5, n_airports=200)
    assert sorted(out) == sorted(a.icao for a in make_airports(200, 5))
    contrast = np.array([v["contrast"] for v in out.values()])
    shoulder = np.array([v["shoulder_m"] for v in out.values()])
    assert np.all(np.abs(contrast) < 0.6) and np.ptp(contrast) > 0.2  # asphalt and concrete against the grass
    has = shoulder > 0
    assert np.all((shoulder[has] >= 3.0) & (shoulder[has] <= 10.0))  # the generator paints 3–10 m shoulders
    assert 0.38 < has.mean() < 0.62  # ... on half of the runways
    assert all(np.isnan(v["shoulder_contrast"]) == (v["shoulder_m"] == 0) for v in out.values())
