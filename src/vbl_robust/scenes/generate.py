"""``generate``: in-memory synthetic approach samples with exact labels (pixels rendered lazily)."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

from vbl_robust.data.sample import Sample
from vbl_robust.geometry.camera import intrinsics, project

from .airports import DEFAULT_POOL, Airport, make_airports
from .envelopes import Approach, Envelope, resolve_envelopes, sample_approach, sample_stream
from .layout import airport_layout, debug_layout
from .render import debug_look, render_scene, sample_look
from .textures import N_WORLDS

_layout = functools.lru_cache(maxsize=64)(airport_layout)


def _world_of(airport: Airport) -> tuple[int, tuple[float, float]]:
    """World raster and offset (metres) that surround ``airport`` (fixed per airport)."""
    rng = np.random.default_rng([airport.seed, 7])
    off = rng.uniform(-4000.0, 4000.0, 2)
    return airport.seed % N_WORLDS, (float(off[0]), float(off[1]))


def render_sample(approach: Approach, airport: Airport, K: np.ndarray, width: int, height: int,
                  render_seed: int, debug: bool = False) -> np.ndarray:
    """Pixels (height, width, 3) uint8 RGB of one approach to ``airport``; same arguments → same pixels."""
    rng = np.random.default_rng(render_seed)
    if debug:
        return render_scene(approach.R, approach.position, K, width, height,
                            debug_layout(airport.length_m, airport.width_m), debug_look())
    world, offset = _world_of(airport)
    look = sample_look(rng, world, offset, airport.azimuth_deg)
    return render_scene(approach.R, approach.position, K, width, height, _layout(airport), look, rng)


def _sample_meta(app: Approach, airport: Airport, envelope: str, fov_deg: float, render_seed: int) -> dict[str, Any]:
    """The ``meta`` of a synthetic sample (keys of :func:`generate`'s Returns, in that order)."""
    return {
        "envelope": envelope,
        "airport": airport.icao,
        "runway": airport.runway,
        "runway_azimuth_deg": airport.azimuth_deg,
        "runway_length_m": airport.length_m,
        "runway_width_m": airport.width_m,
        "yaw": app.yaw_deg,
        "pitch": app.pitch_deg,
        "roll": app.roll_deg,
        "distance_m": app.distance_m,
        "lateral_angle_deg": app.lateral_angle_deg,
        "vertical_angle_deg": app.vertical_angle_deg,
        "ltp_lat": airport.ltp_lat,
        "ltp_lon": airport.ltp_lon,
        "ltp_alt": airport.ltp_alt,
        "fov_deg": float(fov_deg),
        "render_seed": render_seed,
    }


def generate(
    n: int,
    seed: int = 0,
    *,
    width: int = 1024,
    height: int = 1024,
    fov_deg: float = 60.0,
    envelopes: Sequence[str | Envelope] | str = ("far", "medium", "close"),
    weights: Sequence[float] | None = None,
    n_airports: int = DEFAULT_POOL,
    runway_length_range_m: tuple[float, float] | None = None,
    require_visible: bool = True,
    margin_px: float = 8.0,
    eager: bool = False,
    debug: bool = False,
) -> list[Sample]:
    """Generate ``n`` synthetic approach samples (LARD V2 envelopes, synthetic airports, exact labels).

    Sample ``i`` depends only on ``(seed, i)`` and the keyword options, not on ``n``: ``generate(10, s)`` is a
    prefix of ``generate(100, s)``, pixels included. Each sample draws an airport of the pool
    (:func:`.airports.make_airports` of ``seed``), an envelope (``weights``), a pose (see :mod:`.envelopes`;
    ``require_visible`` keeps the whole runway in the image with ``margin_px``) and a rendering seed.

    Args:
        n: number of samples; seed: non-negative integer.
        width, height, fov_deg: image size (pixels) and horizontal field of view (degrees, principal point at
            the image centre as in LARD).
        envelopes, weights: envelopes to draw from and their relative weights (default: equal).
        n_airports: size of the synthetic airport pool.
        runway_length_range_m: runway lengths of the pool (default :data:`.airports.RUNWAY_LENGTH_RANGE_M`).
        eager: render all pixels now (else on first access of ``sample.image``; ``drop_pixels()`` frees them).
        debug: render a black world with a flat white runway (for pixel checks).

    Returns:
        ``n`` :class:`vbl_robust.data.sample.Sample` with ``corners_2d = project(corners_3d, R, position, K)`` exactly
        (floats) and ``meta`` keys ``envelope, airport, runway, runway_azimuth_deg, runway_length_m,
        runway_width_m, yaw, pitch, roll`` (LARD conventions: true heading, 90 + pitch, roll right wing down) plus
        ``distance_m, lateral_angle_deg, vertical_angle_deg`` (as sampled), ``ltp_lat, ltp_lon, ltp_alt``,
        ``fov_deg`` and ``render_seed``.
    """
    if int(n) != n or n < 0:
        raise ValueError(f"n: need a non-negative integer, got {n!r}")
    if int(width) != width or int(height) != height or width < 16 or height < 16:
        raise ValueError(f"width/height: need integers >= 16, got {width} x {height}")
    width, height = int(width), int(height)
    K = intrinsics(width, height, fov_deg)
    envs, p = resolve_envelopes(envelopes, weights)
    airports = make_airports(n_airports, seed, **(
        {} if runway_length_range_m is None else {"length_range_m": tuple(runway_length_range_m)}))
    out = []
    for i in range(int(n)):
        rng = np.random.default_rng(sample_stream(seed, i))
        airport = airports[int(rng.integers(len(airports)))]
        env = envs[int(rng.choice(len(envs), p=p))]
        app = sample_approach(rng, env, airport.length_m, airport.width_m, airport.azimuth_deg,
                              require_visible=require_visible, K=K, width=width, height=height,
                              margin_px=margin_px)
        render_seed = int(rng.integers(0, 2**63))
        s = Sample(
            id=f"synth_s{seed}_{i:06d}", K=K, corners_3d=app.corners_3d,
            corners_2d=project(app.corners_3d, app.R, app.position, K), position=app.position, width=width,
            height=height, R=app.R, meta=_sample_meta(app, airport, env.name, fov_deg, render_seed),
            _loader=functools.partial(render_sample, app, airport, K, width, height, render_seed, debug),
        )
        if eager:
            _ = s.image
        out.append(s)
    return out
