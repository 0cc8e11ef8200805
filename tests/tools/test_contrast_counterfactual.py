"""``tools/contrast_counterfactual.py`` recolours only the grass, to the asked runway − grass contrast."""

from __future__ import annotations

import numpy as np


def test_only_the_grass_changes_and_the_runway_stands_off_it(script):
    from vbl_robust.scenes.airports import make_airports
    from vbl_robust.scenes.layout import airport_layout

    tool = script("tools/contrast_counterfactual.py")
    fn = tool.recoloured_layout(airport_layout, 0.25)
    before = tool.surfaces(3, n_airports=20)
    exact = 0
    for a in make_airports(20, 3):
        old, new = airport_layout(a), fn(a)
        assert np.array_equal(old[1:], new[1:]) and np.array_equal(old[0][:8], new[0][:8])
        grass_before, grass_after = tool._lum(old[0][8:11]), tool._lum(new[0][8:11])
        runway = grass_before + before[a.icao]["contrast"]
        if np.all((new[0][8:11] > 0.0) & (new[0][8:11] < 1.0)):  # no channel clipped: the step is exact
            assert abs(abs(runway - grass_after) - 0.25) < 1e-9
            exact += 1
    assert exact >= 15


def test_no_shoulders_removes_exactly_the_shoulder_rows(script):
    from vbl_robust.scenes.airports import make_airports
    from vbl_robust.scenes.layout import airport_layout

    tool = script("tools/contrast_counterfactual.py")
    fn = tool.shoulderless_layout(airport_layout)
    paint = tool.surfaces(4, n_airports=30)
    with_shoulders = 0
    for a in make_airports(30, 4):
        old, new = airport_layout(a), fn(a)
        has = paint[a.icao]["shoulder_m"] > 0
        with_shoulders += has
        assert len(old) - len(new) == int(has)
        assert all(any(np.array_equal(r, q) for q in old) for r in new)  # nothing else altered
    assert 5 <= with_shoulders <= 25


def test_run_renders_under_the_changed_layout_and_restores_it(script, monkeypatch):
    import importlib

    import vbl_robust.detect.evaluate as ev

    tool = script("tools/contrast_counterfactual.py")
    gen = importlib.import_module("vbl_robust.scenes.generate")
    original, seen = gen._layout, []

    class Lazy:
        @property
        def image(self):
            seen.append(gen._layout)
            return None

    monkeypatch.setattr(ev, "evaluate_detector", lambda det, samples: ("evaluated", len(samples)))
    assert tool.run(None, [Lazy(), Lazy()], "no-shoulders", 0.25) == ("evaluated", 2)
    assert len(seen) == 2 and all(f is not original for f in seen)
    assert gen._layout is original
    tool.run(None, [Lazy()], None, 0.25)
    assert seen[-1] is original
