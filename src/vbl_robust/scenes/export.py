"""``write_dataset``: generate scenes and write them in LARD V2 format (images, ``;`` CSV, runway DB JSON)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from vbl_robust.data.lard_write import write_lard
from vbl_robust.data.sample import Sample
from vbl_robust.geometry.geodesy import runway_db_entry

from .airports import DEFAULT_POOL, REFERENCE_LAT_LON_ALT, make_airports
from .generate import generate


def _streamed(samples: list[Sample]) -> Iterator[Sample]:
    """Yield samples, freeing each one's pixels once the writer has moved on (bounded memory)."""
    for s in samples:
        yield s
        s.drop_pixels()


def write_dataset(out_dir: str | Path, n: int, seed: int = 0, *, image_format: str = "png",
                  n_airports: int = DEFAULT_POOL, **generate_kwargs) -> Path:
    """Generate ``n`` scenes (:func:`.generate`, same seed → same files) and write a LARD V2 dataset.

    The synthetic airports' runway DB (lat/lon/alt and ECEF of corners A–D) is built with
    :func:`vbl_robust.geometry.geodesy.runway_db_entry` from each airport's LTP, azimuth and size, so reading the
    dataset back with :func:`vbl_robust.data.read_lard` gives the same corners and camera positions. The
    ``reference`` column names the generator, the seed and :data:`.airports.REFERENCE_LAT_LON_ALT`.

    Returns:
        Path of the metadata CSV.
    """
    samples = generate(n, seed, n_airports=n_airports, **generate_kwargs)
    used = {s.meta["airport"] for s in samples}
    db = {
        a.icao: {a.runway: runway_db_entry(a.ltp_lat, a.ltp_lon, a.ltp_alt, a.azimuth_deg, a.length_m, a.width_m)}
        for a in make_airports(n_airports, seed) if a.icao in used
    }
    lat, lon, alt = REFERENCE_LAT_LON_ALT
    reference = (f"vbl_robust.scenes seed={seed} synthetic airports near lat={lat} lon={lon} alt={alt} m "
                 f"(offsets of about 0.3 deg per airport)")
    return write_lard(out_dir, _streamed(samples), db, reference=reference, image_format=image_format)
