"""Synthetic approach sequences: frames along a glide path, from the LARD V2 far envelope down to the close one.

Trajectory of sequence ``i`` (all in the runway frame of :mod:`.envelopes`; one airport per sequence)
----------------------------------------------------------------------------------------------------
* Constant ground speed ``v`` (``ground_speed_mps``, default 70 m/s ≈ 136 kt, a typical final approach) towards
  the LTP: frame ``f`` is at time ``t_f = f / rate_hz`` and horizontal distance ``d_f = d_0 − v·t_f``. The
  sequence covers ``v·(frames − 1) / rate_hz`` metres; its last frame's distance is uniform in
  ``[lo, hi − span]`` of ``distance_range_m`` (default 280–6000 m: the close envelope's near end to the far
  envelope's far end), so every frame lies in the range. 20 frames at 10 Hz cover 133 m; 80 frames at 1 Hz
  (79 s) fly most of the approach from far to close.
* Glide path: a straight line at ``γ = glide_deg + U(±glide_jitter_deg)`` (default 3° ± 0.25°) anchored at the
  aiming point 305 m past the LTP, as in LARD (height ``tan γ · (d + 305)``), with a constant lateral path angle
  ``U(±lateral_deg)`` seen from the LTP (a localizer-like line: the lateral offset shrinks towards the runway).
* Attitude: a per-sequence base (yaw offset = crab ``U(±crab_deg)``, aeronautical pitch ``U(pitch_range_deg)``,
  roll 0) plus smooth noise: on each of yaw, pitch and roll a sum of three sinusoids with periods ``U(2, 20)`` s
  and random phases, at most ``attitude_noise_deg`` in all — a function of time, so the same approach sampled at
  another rate sees the same attitudes.
* ``require_visible``: the sequence's draws (not its airport) are repeated until all four corners of the runway
  are inside every frame with ``margin_px`` to spare.
* Appearance: one look per sequence (sun, haze, surroundings: :func:`.render.sample_look`), sensor noise drawn per
  frame.

Determinism: sequence ``i`` of seed ``s`` draws from ``SeedSequence(s, spawn_key=(SEQUENCE_STREAM, i))`` and uses
airport ``i`` of the pool of seed ``s`` (:func:`.airports.make_airport`), so it does not depend on ``n``
(``n = 3`` is a prefix of ``n = 10``) and two sequences never share an airport.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from vbl_robust.data.lard_write import write_lard
from vbl_robust.data.sample import Sample
from vbl_robust.data.sequence import ApproachSequence, flatten
from vbl_robust.geometry.camera import intrinsics, project
from vbl_robust.geometry.geodesy import runway_db_entry

from .airports import MAX_POOL, REFERENCE_LAT_LON_ALT, RUNWAY_LENGTH_RANGE_M, Airport, make_airport
from .envelopes import ENVELOPES, Approach, approach_from_angles, corners_visible, fit_margin
from .export import _streamed
from .generate import _layout, _sample_meta, _world_of, render_sample
from .render import render_scene, sample_look

__all__ = ["SEQUENCE_STREAM", "envelope_of", "generate_sequences", "write_sequences"]

#: ``spawn_key`` prefix of the sequence seed streams (distinct from sample streams ``(i,)`` and airport streams).
SEQUENCE_STREAM = 2**31 - 2
#: Draws of a sequence's trajectory before ``require_visible`` gives up.
MAX_SEQUENCE_TRIES = 200
#: Periods of the attitude noise's sinusoids, seconds.
NOISE_PERIOD_S = (2.0, 20.0)


def envelope_of(distance_m: float) -> str:
    """Name of the LARD V2 envelope whose distance range holds ``distance_m`` (``"close"`` first at a shared
    bound), or ``"outside"``."""
    for name in ("close", "medium", "far"):
        lo, hi = ENVELOPES[name].distance_m
        if lo <= distance_m <= hi:
            return name
    return "outside"


def _smooth_noise(rng: np.random.Generator, amplitude_deg: float, t: np.ndarray) -> np.ndarray:
    """Sum of three sinusoids of ``t`` (seconds) with total amplitude ``amplitude_deg``."""
    w = rng.uniform(0.5, 1.0, 3)
    w = amplitude_deg * w / w.sum()
    period = rng.uniform(*NOISE_PERIOD_S, 3)
    phase = rng.uniform(0.0, 2.0 * math.pi, 3)
    return (w[None] * np.sin(2.0 * math.pi * t[:, None] / period[None] + phase[None])).sum(axis=1)


def _render_frame(approach: Approach, airport: Airport, K: np.ndarray, width: int, height: int, look_seed: int,
                  frame: int, debug: bool) -> np.ndarray:
    """Pixels of one frame: the sequence's look (from ``look_seed``), sensor noise of the frame."""
    if debug:
        return render_sample(approach, airport, K, width, height, look_seed, debug=True)
    world, offset = _world_of(airport)
    look = sample_look(np.random.default_rng(look_seed), world, offset, airport.azimuth_deg)
    return render_scene(approach.R, approach.position, K, width, height, _layout(airport), look,
                        np.random.default_rng([look_seed, frame]))


def _check_positive(name: str, value, *, integer: bool = False, zero: bool = False) -> None:
    ok = not isinstance(value, bool) and isinstance(value, int | float | np.number) and math.isfinite(value)
    ok = ok and (value >= 0 if zero else value > 0) and (not integer or int(value) == value)
    if not ok:
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{name}: need {kind} {'>= 0' if zero else '> 0'}, got {value!r}")


def _check_arguments(n, frames, rate_hz, seed, width, height, ground_speed_mps, distance_range_m, glide_deg,
                     glide_jitter_deg, lateral_deg, crab_deg, pitch_range_deg,
                     attitude_noise_deg) -> tuple[float, float, float]:
    """Check :func:`generate_sequences`' arguments (``ValueError`` naming the bad one); the distance range's
    ``(low, high)`` and the metres one sequence flies."""
    for name, value, integer, zero in (("n", n, True, True), ("frames", frames, True, False),
                                       ("rate_hz", rate_hz, False, False), ("seed", seed, True, True),
                                       ("ground_speed_mps", ground_speed_mps, False, False),
                                       ("glide_jitter_deg", glide_jitter_deg, False, True),
                                       ("lateral_deg", lateral_deg, False, True), ("crab_deg", crab_deg, False, True),
                                       ("attitude_noise_deg", attitude_noise_deg, False, True)):
        _check_positive(name, value, integer=integer, zero=zero)
    if int(n) > MAX_POOL:
        raise ValueError(f"n: at most {MAX_POOL} sequences (one synthetic airport each), got {n}")
    if int(width) != width or int(height) != height or width < 16 or height < 16:
        raise ValueError(f"width/height: need integers >= 16, got {width} x {height}")
    if not (0.5 <= glide_deg - glide_jitter_deg and glide_deg + glide_jitter_deg <= 15.0):
        raise ValueError(f"glide_deg: need 0.5 <= glide_deg ± glide_jitter_deg <= 15 degrees, got {glide_deg} ± "
                         f"{glide_jitter_deg}")
    lo, hi = (float(v) for v in distance_range_m)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise ValueError(f"distance_range_m: need 0 < low <= high metres, got {distance_range_m!r}")
    if not pitch_range_deg[0] <= pitch_range_deg[1]:
        raise ValueError(f"pitch_range_deg: need low <= high, got {pitch_range_deg!r}")
    frames = int(frames)
    span = ground_speed_mps * (frames - 1) / rate_hz
    if span > hi - lo:
        raise ValueError(f"frames/rate_hz: {frames} frames at {rate_hz:g} Hz fly {span:.0f} m at {ground_speed_mps:g} "
                         f"m/s, more than distance_range_m {lo:g}-{hi:g} m allows; use fewer frames or a higher rate")
    return lo, hi, span


def _draw_trajectory(rng: np.random.Generator, i: int, airport: Airport, K: np.ndarray, t: np.ndarray, width: int,
                     height: int, lo: float, hi: float, span: float, *, fov_deg: float, ground_speed_mps: float,
                     glide_deg: float, glide_jitter_deg: float, lateral_deg: float, crab_deg: float,
                     pitch_range_deg: tuple[float, float], attitude_noise_deg: float, require_visible: bool,
                     margin_px: float) -> tuple[list[Approach], float, float, int]:
    """Sequence ``i``'s approaches, one per frame time ``t``, drawn from ``rng`` until the runway stays in view
    (``require_visible``); with its glide-path angle, lateral path angle and the number of draws."""
    frames = len(t)
    margin_px = fit_margin(margin_px, width, height)
    for tries in range(1, MAX_SEQUENCE_TRIES + 1):
        d_end = float(rng.uniform(lo, hi - span))
        gamma = glide_deg + float(rng.uniform(-glide_jitter_deg, glide_jitter_deg))
        lateral = float(rng.uniform(-lateral_deg, lateral_deg))
        yaw = float(rng.uniform(-crab_deg, crab_deg)) + _smooth_noise(rng, attitude_noise_deg, t)
        pitch = float(rng.uniform(*pitch_range_deg)) + _smooth_noise(rng, attitude_noise_deg, t)
        roll = _smooth_noise(rng, attitude_noise_deg, t)
        distance = d_end + ground_speed_mps * (t[-1] - t)
        apps = [approach_from_angles(envelope_of(float(distance[f])), float(distance[f]), lateral, -gamma,
                                     float(yaw[f]), float(pitch[f]), float(roll[f]), airport.length_m,
                                     airport.width_m, airport.azimuth_deg, tries=tries) for f in range(frames)]
        if not require_visible or all(corners_visible(a, K, width, height, margin_px) for a in apps):
            return apps, gamma, lateral, tries
    raise RuntimeError(f"generate_sequences: sequence {i}: no trajectory keeps the whole runway of "
                       f"{airport.icao} in a {width}x{height} image (fov {fov_deg:g}°, margin {margin_px} px) "
                       f"after {MAX_SEQUENCE_TRIES} tries; use a wider field of view or a smaller margin")


def _frame_sample(seq_id: str, f: int, app: Approach, airport: Airport, K: np.ndarray, width: int, height: int,
                  fov_deg: float, look_seed: int, digits: int, debug: bool, extra: dict) -> Sample:
    """Frame ``f`` of sequence ``seq_id`` as a lazily rendered sample; ``extra``: the sequence's meta keys."""
    return Sample(
        id=f"{seq_id}_{f:0{digits}d}", K=K, corners_3d=app.corners_3d,
        corners_2d=project(app.corners_3d, app.R, app.position, K), position=app.position, width=width,
        height=height, R=app.R, meta={**_sample_meta(app, airport, app.envelope, fov_deg, look_seed), **extra},
        _loader=functools.partial(_render_frame, app, airport, K, width, height, look_seed, f, debug),
    )


def generate_sequences(
    n: int,
    frames: int,
    rate_hz: float,
    seed: int = 0,
    *,
    width: int = 1024,
    height: int = 1024,
    fov_deg: float = 60.0,
    ground_speed_mps: float = 70.0,
    distance_range_m: tuple[float, float] = (280.0, 6000.0),
    glide_deg: float = 3.0,
    glide_jitter_deg: float = 0.25,
    lateral_deg: float = 0.5,
    crab_deg: float = 3.0,
    pitch_range_deg: tuple[float, float] = (-3.0, 2.0),
    attitude_noise_deg: float = 0.5,
    runway_length_range_m: tuple[float, float] = RUNWAY_LENGTH_RANGE_M,
    require_visible: bool = True,
    margin_px: float = 8.0,
    debug: bool = False,
) -> list[ApproachSequence]:
    """Generate ``n`` synthetic approach sequences of ``frames`` frames at ``rate_hz`` (see the module docstring).

    Args:
        n: number of sequences (each at its own synthetic airport, at most :data:`.airports.MAX_POOL`).
        frames: frames per sequence (>= 1); rate_hz: frames per second.
        seed: non-negative integer; same arguments → same sequences, pixels included.
        width, height, fov_deg: camera (horizontal field of view, principal point at the centre, as in LARD).
        ground_speed_mps: ground speed towards the runway, m/s.
        distance_range_m: horizontal distances (from the LTP) every frame lies in, metres.
        glide_deg, glide_jitter_deg: glide-path angle and its per-sequence uniform jitter, degrees.
        lateral_deg: per-sequence lateral path angle range (±), degrees.
        crab_deg, pitch_range_deg, attitude_noise_deg: base yaw offset range (±), base aeronautical pitch range and
            the smooth attitude noise amplitude, degrees.
        runway_length_range_m: runway lengths of the airports (default :data:`.airports.RUNWAY_LENGTH_RANGE_M`).
        require_visible, margin_px: keep the whole runway in every frame (redraw the trajectory otherwise).
        debug: black world with a flat white runway.

    Returns:
        ``n`` :class:`~vbl_robust.data.sequence.ApproachSequence` with ``id = "synth_q<seed>_<i>"``, ``times = f / rate_hz``;
        frame samples ``"<id>_<f>"`` carry the :func:`.generate` meta keys (``envelope`` = the LARD envelope of the
        frame's distance, see :func:`envelope_of``) plus ``sequence_id``, ``frame_index``, ``time_s``,
        ``glide_path_deg``, ``ground_speed_mps``.

    Raises:
        ValueError: a bad argument (named), or a sequence longer than ``distance_range_m`` at that speed.
        RuntimeError: no trajectory keeps the runway in view (narrow camera, large margin).
    """
    lo, hi, span = _check_arguments(n, frames, rate_hz, seed, width, height, ground_speed_mps, distance_range_m,
                                    glide_deg, glide_jitter_deg, lateral_deg, crab_deg, pitch_range_deg,
                                    attitude_noise_deg)
    width, height, frames = int(width), int(height), int(frames)
    K = intrinsics(width, height, fov_deg)
    t = np.arange(frames) / float(rate_hz)
    digits = max(4, len(str(frames - 1)))
    out = []
    for i in range(int(n)):
        airport = make_airport(i, seed, length_range_m=tuple(runway_length_range_m))
        rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(SEQUENCE_STREAM, i)))
        apps, gamma, lateral, tries = _draw_trajectory(
            rng, i, airport, K, t, width, height, lo, hi, span, fov_deg=fov_deg, ground_speed_mps=ground_speed_mps,
            glide_deg=glide_deg, glide_jitter_deg=glide_jitter_deg, lateral_deg=lateral_deg, crab_deg=crab_deg,
            pitch_range_deg=pitch_range_deg, attitude_noise_deg=attitude_noise_deg, require_visible=require_visible,
            margin_px=margin_px)
        look_seed = int(rng.integers(0, 2**63))
        seq_id = f"synth_q{seed}_{i:04d}"
        samples = [_frame_sample(seq_id, f, app, airport, K, width, height, fov_deg, look_seed, digits, debug, {
            "sequence_id": seq_id, "frame_index": f, "time_s": float(t[f]), "glide_path_deg": gamma,
            "ground_speed_mps": float(ground_speed_mps)})
            for f, app in enumerate(apps)]
        out.append(ApproachSequence(seq_id, samples, t.copy(), np.arange(frames), meta={
            "airport": airport.icao, "runway": airport.runway, "glide_path_deg": gamma,
            "lateral_angle_deg": lateral, "ground_speed_mps": float(ground_speed_mps), "rate_hz": float(rate_hz),
            "seed": int(seed), "index": i, "tries": tries, "time_source": "generator", "gaps": [],
        }))
    return out


def write_sequences(out_dir: str | Path, n: int, frames: int, rate_hz: float, seed: int = 0, *,
                    image_format: str = "png", **generate_kwargs) -> Path:
    """Generate ``n`` sequences (:func:`generate_sequences`) and write them as one LARD V2 dataset.

    Images are ``images/<sequence id>_<frame>.<fmt>``; the metadata CSV carries the sequence columns
    ``sequence_id, frame_index, time_s`` (:data:`vbl_robust.data.lard.SEQUENCE_COLUMNS`), so
    :func:`vbl_robust.data.read_lard_sequences` gives the sequences back. Returns the metadata CSV path.
    """
    sequences = generate_sequences(n, frames, rate_hz, seed, **generate_kwargs)
    length_range = tuple(generate_kwargs.get("runway_length_range_m", RUNWAY_LENGTH_RANGE_M))
    airports = [make_airport(i, seed, length_range_m=length_range) for i in range(int(n))]
    db = {a.icao: {a.runway: runway_db_entry(a.ltp_lat, a.ltp_lon, a.ltp_alt, a.azimuth_deg, a.length_m, a.width_m)}
          for a in airports}
    lat, lon, alt = REFERENCE_LAT_LON_ALT
    reference = (f"vbl_robust.scenes.generate_sequences seed={seed} frames={frames} rate_hz={rate_hz:g}; synthetic "
                 f"airports near lat={lat} lon={lon} alt={alt} m")
    return write_lard(out_dir, _streamed(flatten(sequences)), db, reference=reference, image_format=image_format)

