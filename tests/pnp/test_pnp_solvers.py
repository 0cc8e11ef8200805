"""OpenCV PnP solvers: results, failure flags on degenerate rows, whole-call errors, ITERATIVE's local minima."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from vbl_robust.pnp import solvers as solvers_mod
from vbl_robust.pnp.solvers import SOLVERS, PnPResult, solve


@pytest.fixture
def near(view):
    return view(800.0, lateral_deg=1.0, yaw_offset_deg=4.0, roll_deg=5.0)


def degenerate_rows(x: np.ndarray) -> dict[str, np.ndarray]:
    """Rows that no solver can use, built from a good row ``x`` (4, 2)."""
    collinear = np.array([[100.0, 100.0], [200.0, 200.0], [300.0, 300.0], [700.0, 200.0]])
    coincident = x.copy()
    coincident[1] = coincident[0]
    all_same = np.repeat(x[:1], 4, axis=0)
    with_nan = x.copy()
    with_nan[2, 1] = np.nan
    with_inf = x.copy()
    with_inf[0, 0] = np.inf
    return {
        "collinear": collinear,
        "coincident": coincident,
        "all_same": all_same,
        "nan": with_nan,
        "inf": with_inf,
        "huge": x * 1e200,
    }


@pytest.mark.parametrize("method", SOLVERS)
def test_exact_corners_give_the_camera(method: str, near) -> None:
    res = solve(near.points_2d, near.corners_3d, near.K, method=method)
    assert isinstance(res, PnPResult) and len(res) == 1 and res.method == method
    assert res.position.shape == (1, 3) and res.position.dtype == np.float64
    assert res.rvec.shape == res.tvec.shape == (1, 3)
    assert res.success.tolist() == [True] and res.reason == ("",)
    np.testing.assert_allclose(res.position[0], near.position, atol=0.05)
    assert res.reproj_error_px[0] < 1e-3
    # C = -R^T t
    np.testing.assert_allclose(res.position[0], -cv2.Rodrigues(res.rvec[0])[0].T @ res.tvec[0])


@pytest.mark.parametrize("method", SOLVERS)
def test_degenerate_rows_fail_without_touching_good_rows(method: str, near) -> None:
    bad = degenerate_rows(near.points_2d)
    batch = np.stack([near.points_2d, *bad.values(), near.points_2d + 0.3])
    res = solve(batch, near.corners_3d, near.K, method=method)
    assert res.success.tolist() == [True] + [False] * len(bad) + [True]
    failed = slice(1, 1 + len(bad))
    assert np.all(np.isnan(res.position[failed])) and np.all(np.isnan(res.reproj_error_px[failed]))
    assert np.all(np.isnan(res.rvec[failed])) and np.all(np.isnan(res.tvec[failed]))
    assert all(res.reason[1 : 1 + len(bad)])
    assert "collinear" in res.reason[1] and "non-finite" in res.reason[4]
    # good rows are exactly what they are when solved alone
    alone = solve(batch[[0, -1]], near.corners_3d, near.K, method=method)
    np.testing.assert_array_equal(res.position[[0, -1]], alone.position)


def test_ragged_batch_fails_only_the_bad_rows(near) -> None:
    rows = [near.points_2d, near.points_2d[:3], None, near.points_2d.tolist()]
    res = solve(rows, near.corners_3d, near.K)
    assert res.success.tolist() == [True, False, False, True]
    assert "(3, 2)" in res.reason[1]
    np.testing.assert_allclose(res.position[3], near.position, atol=1e-3)


def test_unbatched_and_torch_inputs(near) -> None:
    a = solve(near.points_2d, near.corners_3d, near.K)
    b = solve(torch.tensor(near.points_2d[None], requires_grad=True), torch.tensor(near.corners_3d), near.K)
    c = solve(near.points_2d.tolist(), near.corners_3d, near.K)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.position, c.position)
    empty = solve(np.zeros((0, 4, 2)), near.corners_3d, near.K)
    assert empty.position.shape == (0, 3) and empty.success.shape == (0,)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"points_2d": np.zeros((3, 2))}, "points_2d"),
        ({"points_2d": np.zeros((2, 5, 2))}, "points_2d"),
        ({"points_2d": np.zeros((2, 4, 3))}, "points_2d"),
        ({"points_2d": "corners"}, "points_2d"),
        ({"corners_3d": np.zeros((4, 2))}, "corners_3d"),
        ({"corners_3d": np.zeros((4, 3))}, "corners_3d"),
        ({"corners_3d": np.full((4, 3), np.nan)}, "corners_3d"),
        ({"K": np.eye(4)}, "K"),
        ({"K": -np.eye(3)}, "K"),
        ({"method": "epnp"}, "method"),
    ],
)
def test_whole_call_mistakes_raise_naming_the_argument(kwargs, needle, near) -> None:
    args = {"points_2d": near.points_2d, "corners_3d": near.corners_3d, "K": near.K} | kwargs
    with pytest.raises(ValueError, match=needle):
        solve(**args)


def test_solution_behind_the_camera_is_a_failure(near, monkeypatch) -> None:
    behind = (np.zeros(3), np.array([0.0, 0.0, -10.0]))  # identity rotation: the runway is at z < 0
    monkeypatch.setattr(solvers_mod, "_opencv_candidates", lambda *a: [behind])
    for method in ("sqpnp", "ippe"):  # unrefined candidates are checked as they come
        res = solve(near.points_2d, near.corners_3d, near.K, method=method)
        assert not res.success[0] and "behind the camera" in res.reason[0]


@pytest.mark.parametrize("method", SOLVERS)
def test_swapped_far_corners_leave_only_solutions_behind_the_camera(method: str, near) -> None:
    res = solve(near.points_2d[[1, 0, 2, 3]], near.corners_3d, near.K, method=method)
    assert not res.success[0] and "behind the camera" in res.reason[0]


def test_opencv_errors_are_recorded(near, monkeypatch) -> None:
    def boom(*args, **kwargs):
        raise cv2.error("synthetic failure")

    monkeypatch.setattr(cv2, "solvePnPGeneric", boom)
    monkeypatch.setattr(cv2, "solvePnP", boom)
    for method in (*(m for m in SOLVERS if m != "ippe_lm"), solvers_mod.ROWWISE):
        res = solve(near.points_2d, near.corners_3d, near.K, method=method)
        assert not res.success[0] and res.reason[0].startswith("OpenCV error"), method
    # the vectorised ippe_lm calls OpenCV only for rows without a finite IPPE pose
    assert solve(near.points_2d, near.corners_3d, near.K).success[0]


def test_ippe_lm_never_worse_than_plain_ippe_or_iterative_under_noise(view) -> None:
    """notes/pnp.md: plain ITERATIVE lands in wrong local minima on coplanar corners with noise."""
    rng = np.random.default_rng(7)
    worse_minimum = 0
    n = 60
    for _ in range(n):
        v = view(
            rng.uniform(400.0, 700.0), lateral_deg=rng.uniform(-3, 3), yaw_offset_deg=rng.uniform(-10, 10),
            pitch_deg=rng.uniform(-8, 0), roll_deg=rng.uniform(-10, 10),
        )
        x = v.points_2d + rng.normal(0.0, 2.0, size=(4, 2))
        best = solve(x, v.corners_3d, v.K, method="ippe_lm")
        assert best.success[0]
        for method in ("iterative", "ippe"):
            other = solve(x, v.corners_3d, v.K, method=method)
            if other.success[0]:
                assert best.reproj_error_px[0] <= other.reproj_error_px[0] + 1e-9, method
        it = solve(x, v.corners_3d, v.K, method="iterative")
        if not it.success[0] or it.reproj_error_px[0] > best.reproj_error_px[0] + 0.1:
            worse_minimum += 1
    assert worse_minimum >= n // 10, f"ITERATIVE missed the least-squares pose only {worse_minimum}/{n} times"
