"""Properties of the Objective L(θ) (hypothesis), through its public API only:
``Objective(sample, detector, box, pnp="ippe_lm")``, ``objective(theta)`` and ``objective.evaluate(theta)``
(``.loss``, ``.reason``, ``.failed``).

Samples are small synthetic scenes (256 × 256, one per LARD envelope); the detector is the oracle (exact
corners moved by the perturbation, no pixels read), so every check is fast and deterministic.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vbl_robust.constants import NotMeasured, NotMeasuredError
from vbl_robust.data.sample import Sample
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.pipeline import Objective
from vbl_robust.scenes.generate import generate
from vbl_robust.space import ParameterBox

# deterministic in CI, no example database written into the shared working tree
PROPS = settings(max_examples=40, deadline=None, derandomize=True, database=None)
BOX = ParameterBox({"roll_deg": (-20.0, 20.0), "contrast": (0.5, 1.5)})
PENALTY_M = 5000.0
ENVELOPES = ("close", "medium", "far")


@pytest.fixture(scope="module")
def samples():
    return [generate(1, seed=0, width=256, height=256, envelopes=(e,), debug=True)[0] for e in ENVELOPES]


def thetas_in_box(max_rows=8):
    """(N, 2) θ inside BOX, corners of the box included."""
    unit = st.floats(0.0, 1.0) | st.sampled_from([0.0, 0.5, 1.0])
    return st.lists(st.tuples(unit, unit), min_size=1, max_size=max_rows).map(lambda u: BOX.from_unit(np.array(u)))


@PROPS
@given(st.integers(0, len(ENVELOPES) - 1), thetas_in_box())
def test_inside_the_box_the_oracle_error_is_finite_nonnegative_and_zero(samples, k, theta):
    objective = Objective(samples[k], OracleDetector(), BOX, pnp="ippe_lm")
    rec = objective.evaluate(theta)
    assert rec.loss.shape == (theta.shape[0],) and rec.loss.dtype == np.float64
    assert np.isfinite(rec.loss).all() and (rec.loss >= 0).all()
    assert rec.loss.max() < 1e-6, (ENVELOPES[k], theta, rec.loss)  # roll about the optical axis moves no camera
    assert rec.reason == ("",) * theta.shape[0] and not rec.failed.any()
    ev = objective(theta)  # __call__ is evaluate()'s losses and reasons
    np.testing.assert_array_equal(ev.values, rec.loss)
    assert ev.reasons == rec.reason


@settings(PROPS, max_examples=10)
@given(st.integers(0, len(ENVELOPES) - 1), thetas_in_box(max_rows=5), st.booleans())
def test_rows_are_independent_of_the_batch(samples, k, theta, fail_outside):
    """Row i of a batch is the evaluation of θ_i alone (noisy oracle: non-trivial errors and failures)."""
    objective = Objective(samples[k], OracleDetector(fail_outside=fail_outside, noise_px=2.0), BOX, pnp="ippe_lm")
    rec = objective.evaluate(theta)
    for i in range(theta.shape[0]):
        one = objective.evaluate(theta[i : i + 1])
        assert one.reason[0] == rec.reason[i]
        np.testing.assert_allclose(one.loss[0], rec.loss[i], rtol=1e-12, atol=0)


@settings(PROPS, max_examples=30)
@given(st.integers(0, len(ENVELOPES) - 1), thetas_in_box(), st.sampled_from([(False, 2.0), (True, 3.0), (True, 0.0)]))
def test_the_loss_is_the_penalty_exactly_when_a_reason_is_recorded(samples, k, theta, detector_args):
    fail_outside, noise = detector_args
    rec = Objective(samples[k], OracleDetector(fail_outside=fail_outside, noise_px=noise), BOX).evaluate(theta)
    reason = np.array([r != "" for r in rec.reason])
    np.testing.assert_array_equal(rec.failed, reason)
    np.testing.assert_array_equal(rec.loss[reason], PENALTY_M)  # exactly 5000 m
    ok = rec.loss[~reason]
    assert np.isfinite(ok).all() and (ok >= 0).all() and (ok != PENALTY_M).all()  # a success is never the penalty


@settings(PROPS, max_examples=10)
@given(thetas_in_box())
def test_a_sample_without_pixels_is_not_measured_on_any_theta(samples, theta):
    """No θ of a sample without pixels gives a value: not the penalty (a finding), an error the campaign records
    as not measured."""
    s = samples[2]
    bare = Sample(s.id, s.K, s.corners_3d, s.corners_2d, s.position, s.width, s.height, R=s.R,
                  image_path="/nonexistent/vbl_robust/x.png")
    with pytest.raises(NotMeasuredError) as e:
        Objective(bare, OracleDetector(), BOX).evaluate(theta)
    assert e.value.reason is NotMeasured.INPUT_UNAVAILABLE


def test_the_noisy_oracle_does_produce_failures(samples):
    """Guard for the test above: its detectors give both successes and recorded failures in the box."""
    theta = BOX.from_unit(np.random.default_rng(0).random((64, 2)))
    rec = Objective(samples[0], OracleDetector(noise_px=2.0), BOX).evaluate(theta)
    assert rec.failed.any() and not rec.failed.all()


# -- bad θ ---------------------------------------------------------------------------------------------------
@PROPS
@given(st.lists(st.integers(0, 4), min_size=0, max_size=3).map(tuple))
def test_a_theta_of_the_wrong_shape_is_a_value_error(samples, shape):
    if (len(shape) == 2 and shape[1] == BOX.dim) or shape == (BOX.dim,):
        return  # (N, 2) and one row (2,) are valid
    objective = Objective(samples[0], OracleDetector(), BOX)
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        objective.evaluate(np.ones(shape))
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        objective(np.ones(shape))


@PROPS
@given(thetas_in_box(), st.data(), st.sampled_from([np.nan, np.inf, -np.inf]))
def test_a_non_finite_theta_is_a_value_error(samples, theta, data, bad):
    i = data.draw(st.integers(0, theta.shape[0] - 1))
    j = data.draw(st.integers(0, BOX.dim - 1))
    theta = theta.copy()
    theta[i, j] = bad
    with pytest.raises(ValueError, match="finite"):
        Objective(samples[0], OracleDetector(), BOX).evaluate(theta)


def test_one_row_and_empty_batches():
    sample = generate(1, seed=0, width=256, height=256, envelopes=("far",), debug=True)[0]
    objective = Objective(sample, OracleDetector(), BOX)
    assert objective(np.array([3.0, 1.2])).values.shape == (1,)  # a 1-D θ of length d is one row
    rec = objective.evaluate(np.zeros((0, 2)))
    assert rec.loss.shape == (0,) and rec.reason == ()


# -- θ outside the box: the current contract -------------------------------------------------------------------
@PROPS
@given(st.integers(0, len(ENVELOPES) - 1),
       st.lists(st.tuples(st.floats(-180.0, 180.0) | st.sampled_from([-180.0, 90.0, 180.0]),
                          st.floats(0.0, 1e6) | st.sampled_from([0.0, 1e-9, 100.0])),
                min_size=1, max_size=6).map(np.array))
def test_theta_outside_the_box_is_evaluated_as_given(samples, k, theta):
    """The Objective does not check θ against its box: any finite θ in each family's domain is evaluated as given,
    without clipping or error (a roll of ±180°, a contrast of 0 or 10⁶; a roll beyond ±180° is outside roll's
    domain, a ValueError like a negative contrast). With the oracle (which reads no pixels) the contrast has no effect and a roll about the optical
    axis does not move the camera, so the error stays below 1e-6 m. Keeping θ inside the box is the caller's job
    (the searches map the unit cube through ``box.from_unit``)."""
    rec = Objective(samples[k], OracleDetector(), BOX).evaluate(theta)
    assert not rec.failed.any() and np.isfinite(rec.loss).all()
    assert rec.loss.max() < 1e-6, (theta, rec.loss)


@PROPS
@given(st.floats(-1e6, -1e-12))
def test_theta_outside_a_familys_domain_is_a_value_error(samples, c):
    """A negative contrast factor means nothing: a one-line ValueError naming the parameter."""
    with pytest.raises(ValueError, match="contrast must be >= 0"):
        Objective(samples[0], OracleDetector(), BOX).evaluate(np.array([[0.0, c]]))
