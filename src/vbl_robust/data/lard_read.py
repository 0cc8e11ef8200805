"""Reading LARD V2 datasets (metadata CSV + runway DB JSON) into :class:`~vbl_robust.data.sample.Sample` objects.

Conventions: :mod:`.lard` (format, units), :mod:`vbl_robust.geometry.geodesy` (geodesy and camera attitude).

Target runway
    LARD V2 writes one row per runway facing the aircraft, so an image can have several rows; none of them is
    flagged as the scenario's target. Rule used here, per image with more than one row: the target is the runway
    named in the ``scenario`` value or, failing that, in the image file name (LARD names scenarios and images
    ``<ICAO>-<runway>…``, e.g. ``CYEG-20_000.jpg``); if neither names one of the rows' runways, the row with the
    smallest absolute lateral path angle (the runway the aircraft is lined up with) is kept.

Derived columns
    ``slant_distance, along_track_distance, height_above_runway, lateral_path_angle, vertical_path_angle`` are
    recomputed from the geometry (:func:`.lard.approach_metrics`). Values present in the CSV are cross-checked
    within :func:`.lard.metrics_tolerance`; a disagreement does not drop the row: it is listed in
    ``sample.meta["lard_check"]`` (``{field: (stored, computed)}``) and one warning per file is logged.
"""

from __future__ import annotations

import csv
import logging
import math
import re
from collections.abc import Callable
from pathlib import Path, PurePosixPath

import numpy as np

from ..geometry.camera import intrinsics
from ..geometry.geodesy import RunwayFrame
from .lard import (
    CORNER_COLUMNS,
    DERIVED_COLUMNS,
    EXACT_CORNER_COLUMNS,
    METRES_PER_NM,
    REQUIRED_COLUMNS,
    approach_metrics,
    load_runway_db,
    metrics_tolerance,
    normalize_runway,
)
from .paths import resolve_within
from .sample import Sample, load_rgb

logger = logging.getLogger(__name__)

DEFAULT_FOV_DEG = 60.0
_TARGET_RE = re.compile(r"([A-Z]{4})[-_ ]?(?:RWY)?[-_ ]?(\d{1,2}[LCR]?)(?![0-9])")


def read_lard(
    csv_path: str | Path,
    runway_db_path: str | Path,
    *,
    root: str | Path | None = None,
    in_odd_only: bool = False,
    corners_in_image: bool = False,
    fov_deg: float | None = None,
    width: int | None = None,
    height: int | None = None,
    target_runway_only: bool = True,
) -> list[Sample]:
    """Read a LARD V2 metadata CSV and its runway DB into samples (pixels are loaded lazily).

    Args:
        csv_path: ``;``-separated metadata CSV, columns read by name; required: ``image, width, height, airport,
            runway, lat_cam, lon_cam, alt_cam, yaw, pitch, roll, x_TR … y_BR``.
        runway_db_path: LARD runway DB JSON (airport → runway → corners A..D).
        root: dataset root the ``image`` paths are relative to and confined in (default: the CSV's directory).
        in_odd_only: keep only rows with ``runway_in_cone == "IN_ODD"`` (needs that column).
        corners_in_image: keep only rows whose four corners lie inside the image.
        fov_deg: horizontal field of view; default the CSV's ``fov_deg`` column when present, else 60° (LARD V2).
        width, height: image size overriding the CSV's ``width``/``height``.
        target_runway_only: keep one row per image, the scenario's target runway (module docstring); if False,
            keep every row (ids of images with several rows become ``<image>#<runway>``).

    Returns:
        Samples in CSV order: ``id`` = image path relative to the root, ``K`` from the FOV and size,
        ``corners_3d`` (runway frame, from the DB), ``corners_2d`` (``x_TR_exact…`` when present, else the
        truncated labels), ``position``, ``R`` (camera → runway), ``image_path`` and ``meta`` (every CSV field as
        text, plus ``airport``, ``runway``, ``runway_db_key``, ``runway_azimuth_deg``, ``runway_heading_deg``,
        LARD ``yaw``/``pitch``/``roll`` as floats, ``derived`` (recomputed metrics), ``lard_check``, ``row``).

    Raises:
        FileNotFoundError: CSV or DB missing (an image file is only needed when ``sample.image`` is accessed).
        ValueError: one line naming the file, the 1-based data row and image, the field and the value, for a
            missing column, a non-numeric/NaN value, an unknown airport or runway, malformed DB JSON or corners, or
            an image path leaving the root.
    """
    csv_file = Path(csv_path)
    if not csv_file.is_file():
        raise FileNotFoundError(f"{csv_file}: metadata CSV not found")
    db_file = Path(runway_db_path)
    db = load_runway_db(db_file)
    base = Path(root) if root is not None else csv_file.parent
    if width is not None and (int(width) != width or width <= 0):
        raise ValueError(f"read_lard: width must be a positive integer, got {width}")
    if height is not None and (int(height) != height or height <= 0):
        raise ValueError(f"read_lard: height must be a positive integer, got {height}")

    with open(csv_file, newline="", encoding="utf-8-sig") as f:
        reader = csv.DictReader(f, delimiter=";")
        header = [h.strip() for h in (reader.fieldnames or [])]
        reader.fieldnames = header
        missing = [c for c in REQUIRED_COLUMNS if c not in header]
        if missing:
            raise ValueError(f"{csv_file}: missing column(s) {', '.join(missing)}")
        if in_odd_only and "runway_in_cone" not in header:
            raise ValueError(f"{csv_file}: in_odd_only needs the column 'runway_in_cone', which is missing")
        use_exact = all(c in header for c in EXACT_CORNER_COLUMNS)
        frames: dict[tuple[str, str], tuple[RunwayFrame, np.ndarray]] = {}
        records = []
        for i, row in enumerate(reader, start=1):
            row = {k: (v if v is not None else "") for k, v in row.items() if k is not None}
            records.append(_parse_row(row, i, csv_file, db_file, db, frames, base, use_exact,
                                      fov_deg, width, height))

    if target_runway_only:
        records = _select_targets(records)
    else:
        counts: dict[str, int] = {}
        for s in records:
            counts[s.id] = counts.get(s.id, 0) + 1
        for s in records:
            if counts[s.id] > 1:
                s.id = f"{s.id}#{s.meta['runway_db_key']}"
    if in_odd_only:
        records = [s for s in records if s.meta.get("runway_in_cone", "").strip() == "IN_ODD"]
    if corners_in_image:
        records = [s for s in records if s.corners_in_image()]

    flagged = [s for s in records if s.meta["lard_check"]]
    if flagged:
        s = flagged[0]
        logger.warning("%s: %d row(s) have derived columns disagreeing with the geometry, e.g. row %d: %s",
                       csv_file, len(flagged), s.meta["row"], s.meta["lard_check"])
    return records


def _number(row: dict, field: str, where: str) -> float:
    text = row.get(field, "")
    try:
        value = float(str(text).strip())
    except ValueError:
        raise ValueError(f"{where}: field {field!r} = {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: field {field!r} = {text!r} is not a finite number")
    return value


def _size(row: dict, field: str, where: str, override: int | None) -> int:
    if override is not None:
        return int(override)
    value = _number(row, field, where)
    if value <= 0 or value != int(value):
        raise ValueError(f"{where}: field {field!r} = {row[field]!r} is not a positive integer")
    return int(value)


def _parse_row(row, i, csv_file, db_file, db, frames, base, use_exact, fov_deg, width, height) -> Sample:
    image_text = row.get("image", "").strip()
    where = f"{csv_file}: row {i} (image {image_text!r})"
    w = _size(row, "width", where, width)
    h = _size(row, "height", where, height)
    fov = fov_deg if fov_deg is not None else (
        _number(row, "fov_deg", where) if row.get("fov_deg", "").strip() else DEFAULT_FOV_DEG)
    lat, lon, alt = (_number(row, c, where) for c in ("lat_cam", "lon_cam", "alt_cam"))
    yaw, pitch, roll = (_number(row, c, where) for c in ("yaw", "pitch", "roll"))
    if not -90.0 < lat < 90.0:
        raise ValueError(f"{where}: field 'lat_cam' = {row['lat_cam']!r} is not a latitude in (-90, 90)")
    corner_cols = EXACT_CORNER_COLUMNS if use_exact and all(row.get(c, "").strip() for c in
                                                            EXACT_CORNER_COLUMNS) else CORNER_COLUMNS
    uv = np.array([_number(row, c, where) for c in corner_cols]).reshape(4, 2)

    airport = row.get("airport", "").strip().upper()
    if airport not in db:
        raise ValueError(f"{where}: field 'airport' = {row.get('airport')!r} is not in the runway DB {db_file}")
    found = db[airport].get(normalize_runway(row.get("runway", "")))
    if found is None:
        raise ValueError(f"{where}: field 'runway' = {row.get('runway')!r} is not a runway of {airport} in the "
                         f"runway DB {db_file} (has {', '.join(k for k, _ in db[airport].values())})")
    db_key, entry = found
    if (airport, db_key) not in frames:
        try:
            f = RunwayFrame.from_corners(entry)
        except ValueError as exc:
            raise ValueError(f"{db_file}: airport {airport!r} runway {db_key!r}: {exc}") from None
        frames[(airport, db_key)] = (f, f.corners_3d)
    frame, corners_3d = frames[(airport, db_key)]

    path = resolve_within(base, image_text, context=f"{where}: field 'image'")
    position = frame.to_runway(lat, lon, alt)
    derived = approach_metrics(position, corners_3d)
    slant_m = derived["slant_distance"] * METRES_PER_NM
    check = {}
    for field in DERIVED_COLUMNS:
        if row.get(field, "").strip():
            stored = _number(row, field, where)
            if abs(stored - derived[field]) > metrics_tolerance(field, slant_m):
                check[field] = (stored, derived[field])

    meta = dict(row)
    meta.update(
        airport=airport, runway=row.get("runway", "").strip(), runway_db_key=db_key,
        runway_azimuth_deg=frame.azimuth_deg, runway_heading_deg=frame.heading_deg,
        yaw=yaw, pitch=pitch, roll=roll, fov_deg=fov, derived=derived, lard_check=check,
        corners_exact=corner_cols is EXACT_CORNER_COLUMNS, row=i, csv=str(csv_file),
    )
    return Sample(
        id=PurePosixPath(image_text.replace("\\", "/")).as_posix(),
        K=intrinsics(w, h, fov),
        corners_3d=corners_3d,
        corners_2d=uv,
        position=position,
        width=w,
        height=h,
        R=frame.camera_rotation(yaw, pitch, roll),
        image_path=path,
        meta=meta,
        _loader=_image_loader(path, where),
    )


def _image_loader(path: Path, where: str) -> Callable[[], np.ndarray]:
    def load() -> np.ndarray:
        try:
            return load_rgb(path)
        except FileNotFoundError:
            raise FileNotFoundError(f"{where}: image file {path} not found") from None
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None

    return load


def _named_target(s: Sample) -> tuple[str, str] | None:
    for text in (s.meta.get("scenario", ""), PurePosixPath(s.id).stem):
        for m in _TARGET_RE.finditer(str(text)):
            return m.group(1).upper(), normalize_runway(m.group(2))
    return None


def _select_targets(samples: list[Sample]) -> list[Sample]:
    groups: dict[str, list[Sample]] = {}
    for s in samples:
        groups.setdefault(s.id, []).append(s)
    keep = set()
    for rows in groups.values():
        if len(rows) == 1:
            keep.add(id(rows[0]))
            continue
        target = _named_target(rows[0])
        chosen = [s for s in rows if target == (s.meta["airport"], normalize_runway(s.meta["runway"]))]
        if chosen:
            keep.add(id(chosen[0]))
        else:
            best = min(rows, key=lambda s: abs(s.meta["derived"]["lateral_path_angle"]))
            logger.debug("%s: no target runway named; kept %s (smallest lateral path angle)", best.id,
                         best.meta["runway"])
            keep.add(id(best))
    return [s for s in samples if id(s) in keep]
