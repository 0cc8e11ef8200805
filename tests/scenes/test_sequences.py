"""Synthetic approach sequences: determinism, glide-path geometry, visibility, argument errors."""

import math

import numpy as np
import pytest

import vbl_robust as vr
from vbl_robust.data.sequence import ApproachSequence
from vbl_robust.scenes.envelopes import GLIDE_PATH_ANCHOR_M
from vbl_robust.scenes.sequences import envelope_of, generate_sequences

SMALL = {"width": 96, "height": 96}


def test_same_seed_same_sequences_and_prefix():
    a = generate_sequences(2, 4, 5.0, seed=3, **SMALL)
    b = generate_sequences(3, 4, 5.0, seed=3, **SMALL)
    for x, y in zip(a, b[:2], strict=True):
        assert x.id == y.id and [s.id for s in x] == [s.id for s in y]
        for s, t in zip(x, y, strict=True):
            np.testing.assert_array_equal(s.position, t.position)
            np.testing.assert_array_equal(s.R, t.R)
            np.testing.assert_array_equal(s.corners_2d, t.corners_2d)
        np.testing.assert_array_equal(x[0].image, y[0].image)
        np.testing.assert_array_equal(x[-1].image, y[-1].image)
    c = generate_sequences(1, 4, 5.0, seed=4, **SMALL)[0]
    assert not np.array_equal(c[0].position, a[0][0].position)
    # one airport per sequence; frames of a sequence share the look but not the sensor noise
    assert len({q[0].meta["airport"] for q in b}) == 3
    assert not np.array_equal(a[0][0].image, a[0][1].image)


def test_frames_follow_a_three_degree_glide_path():
    seqs = generate_sequences(4, 10, 2.0, seed=0, **SMALL)
    for q in seqs:
        assert isinstance(q, ApproachSequence) and len(q) == 10
        gamma = q.meta["glide_path_deg"]
        assert abs(gamma - 3.0) <= 0.25
        d = q.distances_m
        z = np.array([s.position[2] for s in q])
        # height above the LTP = tan(γ) · (distance + 305 m), the LARD anchor
        np.testing.assert_allclose(z, math.tan(math.radians(gamma)) * (d + GLIDE_PATH_ANCHOR_M), rtol=1e-12)
        slope = np.polyfit(d, z, 1)[0]
        assert slope == pytest.approx(math.tan(math.radians(3.0)), abs=0.005)
        # constant ground speed towards the runway, times f / rate
        np.testing.assert_allclose(np.diff(d), -70.0 / 2.0, rtol=1e-9)
        np.testing.assert_allclose(q.times, np.arange(10) / 2.0)
        assert q.rate_hz == pytest.approx(2.0)
        assert np.all((d >= 280.0) & (d <= 6000.0))
        for f, s in enumerate(q):
            assert s.meta["sequence_id"] == q.id and s.meta["frame_index"] == f and s.meta["time_s"] == f / 2.0
            assert s.meta["envelope"] == envelope_of(s.meta["distance_m"])
            assert abs(s.meta["roll"]) <= 0.5 + 1e-9  # attitude noise only
            assert abs(s.meta["pitch"] - 90.0) <= 3.5
            assert s.corners_in_image(margin_px=8.0)
            np.testing.assert_allclose(s.corners_2d, vr.geometry.camera.project(s.corners_3d, s.R, s.position, s.K),
                                       atol=1e-9)


def test_a_long_slow_sequence_flies_from_far_to_close():
    q = generate_sequences(1, 80, 1.0, seed=1, **SMALL)[0]
    envs = [s.meta["envelope"] for s in q]
    assert envs[0] == "far" and envs[-1] == "close" and "medium" in envs
    # the attitude noise is smooth: small changes from one frame to the next
    roll = np.array([s.meta["roll"] for s in q])
    assert np.max(np.abs(np.diff(roll))) < 0.5


def test_envelope_of():
    assert [envelope_of(d) for d in (280.0, 2500.0, 3000.0, 6000.0, 7000.0)] == [
        "close", "close", "medium", "far", "outside"]


@pytest.mark.parametrize("kwargs, message", [
    ({"n": -1}, "n: need an integer >= 0"),
    ({"frames": 0}, "frames: need an integer > 0"),
    ({"rate_hz": 0.0}, "rate_hz"),
    ({"frames": 200, "rate_hz": 1.0}, "frames/rate_hz: 200 frames at 1 Hz fly 13930 m"),
    ({"glide_deg": 0.2}, "glide_deg"),
    ({"distance_range_m": (500.0, 100.0)}, "distance_range_m"),
])
def test_bad_arguments_are_named(kwargs, message):
    args = {"n": 1, "frames": 3, "rate_hz": 1.0, **kwargs}
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        generate_sequences(args.pop("n"), args.pop("frames"), args.pop("rate_hz"), **args, **SMALL)
