"""A small pool of synthetic airports, each with one target runway.

Every airport of a pool is drawn from the dataset seed (``SeedSequence(seed, spawn_key=(AIRPORT_STREAM, j))``),
so a training set and a test set with different seeds also see different airports. Airports sit at
:data:`REFERENCE_LAT_LON_ALT` plus small offsets (about 0.3° apart, so their scenes never overlap), which is where
a LARD-V2-format export places them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Reference position of the synthetic airports: latitude (deg), longitude (deg), altitude (m, runway DB datum).
REFERENCE_LAT_LON_ALT = (44.0, 2.0, 150.0)

#: ``spawn_key`` prefix of the airport seed streams (sample streams use ``(i,)`` with ``i`` < this value).
AIRPORT_STREAM = 2**31 - 1

#: airports in a synthetic pool unless asked otherwise (``generate(n_airports=...)``)
DEFAULT_POOL = 10

RUNWAY_LENGTH_RANGE_M = (1500.0, 4000.0)
RUNWAY_WIDTH_RANGE_M = (30.0, 60.0)

#: largest synthetic pool (airport codes ``X1000`` … ``X9999`` beyond ``XS99`` / ``X100``–``X999``)
MAX_POOL = 9999


@dataclass(frozen=True)
class Airport:
    """A synthetic airport with one target runway (and optional distractors, see :mod:`.layout`).

    Attributes:
        icao: ICAO-like code, ``"XS01"`` … (X = not a real ICAO region).
        runway: LARD-like designation of the target runway (``"09"``, ``"27L"``), from the azimuth.
        azimuth_deg: true azimuth LTP → FPAP, degrees in [0, 360).
        length_m, width_m: runway size, metres.
        ltp_lat, ltp_lon, ltp_alt: landing threshold point (degrees, degrees, metres).
        seed: integer seeding the airport's layout and surroundings (fixed per airport).
        parallel_side: side of a parallel distractor runway (+1 left, −1 right, 0 none) as seen on the approach;
            it fixes the L/R letter of the designation.
    """

    icao: str
    runway: str
    azimuth_deg: float
    length_m: float
    width_m: float
    ltp_lat: float
    ltp_lon: float
    ltp_alt: float
    seed: int
    parallel_side: int = 0


def designation(azimuth_deg: float, letter: str = "") -> str:
    """Runway designation from a true azimuth: ``round(az / 10)`` in 1..36, two digits, plus ``letter``."""
    n = int(np.floor(azimuth_deg / 10.0 + 0.5)) % 36
    return f"{36 if n == 0 else n:02d}{letter}"


def make_airport(j: int, seed: int, *, length_range_m: tuple[float, float] = RUNWAY_LENGTH_RANGE_M,
                 width_range_m: tuple[float, float] = RUNWAY_WIDTH_RANGE_M) -> Airport:
    """Airport ``j`` of the pool of dataset ``seed`` (deterministic).

    ``length_range_m`` / ``width_range_m``: uniform ranges of the runway size (metres). With the defaults an
    airport is the same as in every earlier release; a wider range rescales the same draws.
    Positions: a 10 × 100 grid 0.3° apart per block of 1000 airports, blocks 3° apart in longitude.
    """
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(AIRPORT_STREAM, int(j))))
    azimuth = float(rng.uniform(0.0, 360.0))
    length = float(rng.uniform(*length_range_m))
    width = float(rng.uniform(*width_range_m))
    parallel_side = int(rng.choice([0, 0, 1, -1]))
    letter = {0: "", 1: "R", -1: "L"}[parallel_side]  # distractor on the left -> we land on the right runway
    lat0, lon0, alt0 = REFERENCE_LAT_LON_ALT
    return Airport(
        icao=f"XS{j + 1:02d}" if j < 99 else f"X{j + 1:03d}",
        runway=designation(azimuth, letter),
        azimuth_deg=azimuth,
        length_m=length,
        width_m=width,
        ltp_lat=lat0 + 0.3 * ((j // 10) % 100) + float(rng.uniform(-0.05, 0.05)),
        ltp_lon=lon0 + 3.0 * (j // 1000) + 0.3 * (j % 10) + float(rng.uniform(-0.05, 0.05)),
        ltp_alt=alt0 + float(rng.uniform(0.0, 300.0)),
        seed=int(rng.integers(0, 2**62)),
        parallel_side=parallel_side,
    )


def make_airports(n: int, seed: int = 0, *, length_range_m: tuple[float, float] = RUNWAY_LENGTH_RANGE_M,
                  width_range_m: tuple[float, float] = RUNWAY_WIDTH_RANGE_M) -> list[Airport]:
    """The pool of ``n`` synthetic airports of dataset ``seed``; airport ``j`` does not depend on ``n``."""
    if int(n) != n or n < 1:
        raise ValueError(f"n_airports: need a positive integer, got {n!r}")
    if int(n) > MAX_POOL:
        raise ValueError(f"n_airports: at most {MAX_POOL} synthetic airports, got {n}")
    for name, (lo, hi) in (("length_range_m", length_range_m), ("width_range_m", width_range_m)):
        if not (np.isfinite(lo) and np.isfinite(hi) and 0 < lo <= hi):
            raise ValueError(f"{name}: need 0 < lo <= hi metres, got {(lo, hi)!r}")
    return [make_airport(j, seed, length_range_m=length_range_m, width_range_m=width_range_m)
            for j in range(int(n))]
