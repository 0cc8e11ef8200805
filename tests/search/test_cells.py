"""``Optimizer.cells()``: the cover of the box kept by the DIRECT family and the grid (None for the others)."""

from __future__ import annotations

import numpy as np
import pytest

from vbl_robust.search.api import METHODS, make_optimizer
from vbl_robust.search.bounds import sound_upper_bound
from vbl_robust.search.cells import Cells
from vbl_robust.space import ParameterBox

from .conftest import bumpy

COVERS = sorted(m for m, cls in METHODS.items() if cls.covers)


def run(method, box, f, **kw):
    opt = make_optimizer(method, box, **kw)
    while len(x := opt.ask()):
        opt.tell(x, f(x))
    return opt


def test_which_methods_keep_a_cover():
    assert COVERS == ["direct", "direct-l", "georobust", "georobust-a", "georobust-av", "grid"]


@pytest.mark.parametrize("method", ["random", "sobol", "apgd"])
def test_methods_without_a_cover_have_no_cells(method, box2):
    opt = make_optimizer(method, box2, max_evals=20)
    if not opt.needs_gradient:
        opt = run(method, box2, bumpy, max_evals=20)
    assert opt.cells() is None


@pytest.mark.parametrize("method", COVERS)
def test_cells_tile_the_box_with_their_evaluated_points(method, box2):
    opt = make_optimizer(method, box2, max_evals=120)
    assert opt.cells() is None  # nothing told yet
    opt = run(method, box2, bumpy, max_evals=120, lipschitz=(3.0, 8.0))
    c = opt.cells()
    assert isinstance(c, Cells) and c.method == method and c.box == box2
    assert abs(c.fractions.sum() - 1.0) < 1e-12
    # every centre is a told point, bit for bit, and its value is the told value
    told = {tuple(x): v for x, v in zip(opt.result().xs.tolist(), opt.result().fs.tolist(), strict=True)}
    for x, v in zip(c.centers.tolist(), c.values.tolist(), strict=True):
        assert told[tuple(x)] == v
    assert np.all(c.lower <= c.centers) and np.all(c.centers <= c.upper)
    assert np.all(c.centers - c.lower <= c.half_widths) and np.all(c.upper - c.centers <= c.half_widths)
    assert box2.contains(c.lower).all() and box2.contains(c.upper).all()
    # the real-unit volumes agree with the exact fractions: no overlap, no gap
    vol = np.prod(c.upper - c.lower, axis=1) / box2.volume
    np.testing.assert_allclose(vol, c.fractions, rtol=1e-9)
    # the same cover gives the optimizer's sound bound
    assert sound_upper_bound(c.values, c.half_widths, (3.0, 8.0), "2") == pytest.approx(opt.upper_bound(), rel=1e-12)
    assert c.lipschitz_estimate is not None and c.lipschitz_estimate > 0


@pytest.mark.parametrize("method", COVERS)
def test_cells_of_1d_runs_are_contiguous_intervals(method):
    box = ParameterBox({"roll_deg": (-15.0, 15.0)})
    c = run(method, box, lambda x: np.sin(x[:, 0]), max_evals=50).cells()
    o = np.argsort(c.lower[:, 0])
    lo, hi = c.lower[o, 0], c.upper[o, 0]
    assert lo[0] == -15.0 and hi[-1] == 15.0
    np.testing.assert_allclose(lo[1:], hi[:-1], atol=1e-12)


def test_an_incomplete_grid_lists_its_unevaluated_nodes_as_failed():
    box = ParameterBox({"a": (0.0, 1.0), "b": (0.0, 2.0)})
    opt = run("grid", box, lambda x: x[:, 0] * 10, counts=(5, 3), order="center-out", batch_size=4, stop_above=5.5)
    c = opt.cells()
    assert len(c) == 15 and opt.nfev < 15
    assert c.failed.sum() == 15 - opt.nfev and np.isnan(c.values[c.failed]).all()
    assert abs(c.fractions.sum() - 1.0) < 1e-12
    # nodes on the edge are clipped cells: a quarter of the area at a corner, and the radius stays half a spacing
    corner = np.flatnonzero(np.all(c.centers == [0.0, 0.0], axis=1))[0]
    assert c.fractions[corner] == pytest.approx(1 / 4 / 4 / 2)
    np.testing.assert_allclose(c.half_widths[corner], [0.125, 0.5])


def test_failed_rectangles_are_marked_and_have_no_value(box2):
    f = lambda x: np.where(x[:, 0] > 3.0, np.nan, bumpy(x))  # noqa: E731
    c = run("georobust", box2, f, max_evals=80).cells()
    assert c.failed.any() and np.isnan(c.values[c.failed]).all() and np.isfinite(c.values[~c.failed]).all()
