"""The sustained error S_k and the breach runs: golden values, brute force, gradients."""

import numpy as np
import pytest
import torch

from vbl_robust.sequences.sustain import breach_runs, breach_summary, sustained, sustained_torch


def _brute(e, k):
    return max(min(e[j:j + k]) for j in range(len(e) - k + 1))


def test_sustained_matches_brute_force_and_limits():
    rng = np.random.default_rng(0)
    e = rng.uniform(0, 10, size=(9, 6))
    for k in range(1, 10):
        v, start = sustained(e, k)
        np.testing.assert_array_equal(v, [_brute(e[:, i], k) for i in range(6)])
        np.testing.assert_array_equal(v, e[start, np.arange(6)] if k == 1 else v)
        t = sustained_torch(torch.as_tensor(e), k)
        np.testing.assert_array_equal(t.numpy(), v)
    np.testing.assert_array_equal(sustained(e, 1)[0], e.max(axis=0))
    np.testing.assert_array_equal(sustained(e, 9)[0], e.min(axis=0))


def test_golden_values_and_first_window():
    v, start = sustained(np.array([1.0, 9.0, 8.0, 2.0, 9.0, 8.0]), 2)
    assert v.tolist() == [8.0] and start.tolist() == [1]  # the first window reaching the maximum


def test_gradient_goes_to_the_frame_that_sets_the_value():
    e = torch.tensor([[1.0], [9.0], [8.0], [2.0]], dtype=torch.float64, requires_grad=True)
    sustained_torch(e, 2).sum().backward()
    assert e.grad[:, 0].tolist() == [0.0, 0.0, 1.0, 0.0]


@pytest.mark.parametrize("k", [0, 5, 1.5, True])
def test_bad_sustain_is_named(k):
    with pytest.raises(ValueError, match="sustain: need an integer k with 1 <= k <= 4"):
        sustained(np.zeros(4), k)


def test_breach_runs_and_summary():
    assert breach_runs([]) == []
    assert breach_runs([True, True, False, True]) == [(0, 2), (3, 1)]
    e = np.array([10.0, 2000.0, 10.0, 5000.0, 5000.0, 3000.0, 10.0, 1500.0])
    d = 1000.0 - 100.0 * np.arange(8)
    t = 0.1 * np.arange(8)
    s = breach_summary(e, d, t, 3, 1000.0)
    assert s == {"sustained_m": 3000.0, "window_start": 3, "breached_frames": 5, "longest_run_frames": 3,
                 "longest_run_start": 3, "longest_run_s": pytest.approx(0.2), "breach_start_frame": 3,
                 "breach_start_m": 700.0, "first_breach_m": 900.0}
    quiet = breach_summary(np.full(8, 10.0), d, np.full(8, np.nan), 2, 1000.0)
    assert quiet["longest_run_frames"] == 0 and quiet["breach_start_m"] is None and quiet["first_breach_m"] is None
    assert breach_summary(e, d, np.full(8, np.nan), 4, 1000.0)["breach_start_m"] is None
