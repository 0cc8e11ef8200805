"""Reading LARD V2 datasets (metadata CSV + runway DB JSON) into :class:`~vbl_robust.data.sample.Sample` objects.

Conventions: :mod:`.lard` (format, units), :mod:`vbl_robust.geometry.geodesy` (geodesy and camera attitude).

Target runway
    LARD V2 writes one row per runway facing the aircraft, so an image can have several rows; none of them is
    flagged as the scenario's target. Rule used here, per image with more than one row: the target is the runway
    named in the ``scenario`` value or, failing that, in the image file name (LARD names scenarios and images
    ``<ICAO>-<runway>…``, e.g. ``CYEG-20_000.jpg``); if neither names one of the rows' runways, the row with the
    smallest absolute lateral path angle (the runway the aircraft is lined up with) is kept.

Checks: what is an error, what is recorded
    A user mistake is a one-line ``ValueError`` naming the file, the 1-based data row, the image, the field and
    the value: a row with more or fewer fields than the header, a duplicated header column, a missing, empty,
    non-numeric or non-finite number, a value outside :data:`FIELD_RANGES` (these angles and altitudes are not
    attitudes but swapped or mis-converted columns), an exact corner column empty while the others of the row
    are filled, an unknown airport or runway, degenerate runway corners, an image path leaving the root, the same
    image and runway on two rows. Nothing is skipped silently.

    An *inconsistency* between fields does not drop the row: it is listed in ``sample.meta["lard_check"]``
    (``{field: (stored, computed)}``) and one warning per file is logged. Checked: the derived columns
    ``slant_distance, along_track_distance, height_above_runway, lateral_path_angle, vertical_path_angle``,
    recomputed from the geometry (:func:`.lard.approach_metrics`), within :func:`.lard.metrics_tolerance`; the
    corner labels against the projection of the DB corners with the row's camera (``x_TR … y_BR`` within
    :data:`LABEL_TOL_PX`, the exact columns within :data:`EXACT_TOL_PX`, both plus :data:`RELATIVE_TOL_PX` of the
    distance from the principal point; corners behind the camera are not compared); and, when the exact columns
    are used, the truncated labels against them (within 1 px).
"""

from __future__ import annotations

import csv
import logging
import math
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from ..geometry.camera import intrinsics, project
from ..geometry.geodesy import DB_CORNERS, RunwayFrame
from .lard import (
    ALTITUDE_RANGE_M,
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
#: Accepted values of the CSV's coordinates, angles (degrees) and altitude (metres): ``(low, high, inclusive)``.
FIELD_RANGES = {
    "lat_cam": (-90.0, 90.0, False),
    "lon_cam": (-180.0, 180.0, True),
    "alt_cam": (*ALTITUDE_RANGE_M, True),
    "yaw": (-360.0, 360.0, True),
    "pitch": (0.0, 180.0, True),  # stored as 90 + aeronautical pitch
    "roll": (-180.0, 180.0, True),
    "fov_deg": (0.0, 180.0, False),
}
#: Largest image side accepted, pixels (``width``, ``height``).
MAX_IMAGE_SIZE_PX = 100_000
#: ``runway_in_cone`` values of LARD V2 (checked when ``in_odd_only`` uses the column).
RUNWAY_IN_CONE = ("IN_ODD", "IN_EXTENDED_ODD", "OUT_OF_ODD", "UNKNOWN")
#: Corner-label reprojection tolerances, pixels: truncated labels lie within 1 px of the projection, plus the
#: 1–3 px by which the LARD labeller's geodesy differs from this package's; exact labels (written by this
#: package) reproject to rounding error; far off-image corners amplify small pose errors (relative term).
LABEL_TOL_PX = 4.0
EXACT_TOL_PX = 0.05
RELATIVE_TOL_PX = 1e-3
#: Smallest runway width (near and far ends) and length accepted from the DB, metres.
MIN_RUNWAY_WIDTH_M = 0.1
MIN_RUNWAY_LENGTH_M = 1.0
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
        ValueError: one line naming the file, the 1-based data row and image, the field and the value, for
            every user mistake listed in the module docstring (malformed rows, bad or out-of-range values, unknown
            airport or runway, malformed DB JSON or corners, an image path leaving the root, duplicated rows), or
            naming the argument for a bad ``width``/``height``/``fov_deg``. Inconsistent rows are not errors:
            see ``meta["lard_check"]``.
    """
    csv_file = Path(csv_path)
    if not csv_file.is_file():
        raise FileNotFoundError(f"{csv_file}: metadata CSV not found")
    db_file = Path(runway_db_path)
    db = load_runway_db(db_file)
    base = Path(root) if root is not None else csv_file.parent
    for name, value in (("width", width), ("height", height)):
        if value is not None and not (_positive_integer(value) and value <= MAX_IMAGE_SIZE_PX):
            raise ValueError(f"read_lard: {name} must be a positive integer <= {MAX_IMAGE_SIZE_PX}, got {value!r}")
    if fov_deg is not None and not (_real(fov_deg) and 0.0 < fov_deg < 180.0):
        raise ValueError(f"read_lard: fov_deg must be a number in (0, 180), got {fov_deg!r}")

    records = _read_rows(csv_file, db_file, db, base, in_odd_only, fov_deg, width, height)
    records = _keep(records, csv_file, in_odd_only, target_runway_only, corners_in_image)
    flagged = [s for s in records if s.meta["lard_check"]]
    if flagged:
        s = flagged[0]
        logger.warning("%s: %d row(s) have derived columns or corner labels disagreeing with the geometry, e.g. "
                       "row %d: %s", csv_file, len(flagged), s.meta["row"], s.meta["lard_check"])
    return records


def _read_rows(csv_file: Path, db_file: Path, db, base: Path, in_odd_only: bool, fov_deg: float | None,
               width: int | None, height: int | None) -> list[Sample]:
    """Every data row of ``csv_file`` as a sample (:func:`_parse_row`), in CSV order; ``ValueError`` for a
    malformed file or row, or an image and runway given twice."""
    records = []
    line = 0
    try:
        with open(csv_file, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f, delimiter=";")
            header = [h.strip() for h in next(reader, [])]
            line = reader.line_num
            _check_header(header, csv_file, in_odd_only)
            use_exact = all(c in header for c in EXACT_CORNER_COLUMNS)
            frames: dict[tuple[str, str], tuple[RunwayFrame, np.ndarray]] = {}
            seen: dict[tuple[str, str, str], int] = {}
            i = 0
            for values in reader:
                line = reader.line_num
                if not values:  # a blank line
                    continue
                i += 1
                if len(values) != len(header):
                    image = values[header.index("image")] if len(values) > header.index("image") else ""
                    raise ValueError(f"{csv_file}: row {i} (image {image.strip()!r}): {len(values)} field(s), the "
                                     f"header has {len(header)} (a missing or extra ';'?)")
                row = {k: v for k, v in zip(header, values, strict=True) if k}
                s = _parse_row(row, i, csv_file, db_file, db, frames, base, use_exact, fov_deg, width, height)
                key = (s.id, s.meta["airport"], s.meta["runway_db_key"])
                if key in seen:
                    raise ValueError(f"{csv_file}: row {i} (image {s.id!r}): same image and runway "
                                     f"{s.meta['airport']} {s.meta['runway_db_key']} as row {seen[key]}")
                seen[key] = i
                records.append(s)
    except UnicodeDecodeError as exc:
        raise ValueError(f"{csv_file}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except csv.Error as exc:
        raise ValueError(f"{csv_file}: line {line + 1}: malformed CSV ({exc})") from None
    return records


def _keep(records: list[Sample], csv_file: Path, in_odd_only: bool, target_runway_only: bool,
          corners_in_image: bool) -> list[Sample]:
    """The rows :func:`read_lard` keeps (its ``in_odd_only``, ``target_runway_only`` and ``corners_in_image``)."""
    if in_odd_only:
        for s in records:
            value = s.meta.get("runway_in_cone", "")
            if value.strip() not in RUNWAY_IN_CONE:
                raise ValueError(f"{csv_file}: row {s.meta['row']} (image {s.id!r}): field 'runway_in_cone' = "
                                 f"{value!r} is not one of {', '.join(RUNWAY_IN_CONE)}")
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
    return records


def _check_header(header: list[str], csv_file: Path, in_odd_only: bool) -> None:
    names = [h for h in header if h]  # an empty name (a trailing ';') is ignored
    dup = sorted({h for h in names if names.count(h) > 1})
    if dup:
        raise ValueError(f"{csv_file}: column(s) {', '.join(dup)} appear more than once in the header")
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise ValueError(f"{csv_file}: missing column(s) {', '.join(missing)}")
    if in_odd_only and "runway_in_cone" not in header:
        raise ValueError(f"{csv_file}: in_odd_only needs the column 'runway_in_cone', which is missing")


def _real(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool | np.bool_) \
        and math.isfinite(value)


def _positive_integer(value) -> bool:
    return _real(value) and value > 0 and int(value) == value


def _number(row: dict, field: str, where: str) -> float:
    text = row.get(field, "")
    try:
        value = float(text.strip())
    except ValueError:
        raise ValueError(f"{where}: field {field!r} = {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{where}: field {field!r} = {text!r} is not a finite number")
    limits = FIELD_RANGES.get(field)
    if limits is not None:
        lo, hi, inclusive = limits
        if not (lo <= value <= hi if inclusive else lo < value < hi):
            interval = f"[{lo:g}, {hi:g}]" if inclusive else f"({lo:g}, {hi:g})"
            raise ValueError(f"{where}: field {field!r} = {text!r} is not in {interval}")
    return value


def _size(row: dict, field: str, where: str, override: int | None) -> int:
    if override is not None:
        return int(override)
    value = _number(row, field, where)
    if value <= 0 or value != int(value) or value > MAX_IMAGE_SIZE_PX:
        raise ValueError(f"{where}: field {field!r} = {row[field]!r} is not a positive integer "
                         f"<= {MAX_IMAGE_SIZE_PX}")
    return int(value)


def _runway_frame(entry, airport: str, db_key: str, db_file: Path) -> tuple[RunwayFrame, np.ndarray]:
    where = f"{db_file}: airport {airport!r} runway {db_key!r}"
    if isinstance(entry, dict):  # a fifth corner would be ignored silently: the DB is not what its author meant
        extra = sorted(str(k) for k, v in entry.items() if k not in DB_CORNERS and isinstance(v, dict)
                       and ("coordinate" in v or "position" in v))
        if extra:
            raise ValueError(f"{where}: corner(s) {', '.join(extra)} beside {', '.join(DB_CORNERS)}: a runway has "
                             "four corners")
    try:
        frame = RunwayFrame.from_corners(entry)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    k = frame.corners_3d
    widths = (float(np.linalg.norm(k[0] - k[1])), float(np.linalg.norm(k[2] - k[3])))
    length = float(np.linalg.norm(0.5 * (k[0] + k[1]) - 0.5 * (k[2] + k[3])))
    if not np.isfinite(k).all() or min(widths) < MIN_RUNWAY_WIDTH_M or length < MIN_RUNWAY_LENGTH_M:
        raise ValueError(f"{where}: degenerate runway corners (widths A-B {widths[0]:.3g} m, C-D {widths[1]:.3g} m, "
                         f"length {length:.3g} m)")
    return frame, k


def _corner_check(uv, names, projected, K, tol_px) -> dict[str, tuple[float, float]]:
    """``{column: (stored, projected)}`` for label coordinates farther than the tolerance from the projection."""
    out = {}
    centre = K[:2, 2]
    for k in range(4):
        if not np.isfinite(projected[k]).all():  # behind the camera: LARD's label is not a projection
            continue
        tol = tol_px + RELATIVE_TOL_PX * float(np.linalg.norm(projected[k] - centre))
        for j in range(2):
            if not abs(uv[k, j] - projected[k, j]) <= tol:  # (also flags a non-finite tolerance)
                out[names[2 * k + j]] = (float(uv[k, j]), float(projected[k, j]))
    return out


def _parse_row(row, i, csv_file, db_file, db, frames, base, use_exact, fov_deg, width, height) -> Sample:
    image_text = row.get("image", "").strip()
    where = f"{csv_file}: row {i} (image {image_text!r})"
    w = _size(row, "width", where, width)
    h = _size(row, "height", where, height)
    fov = fov_deg if fov_deg is not None else (
        _number(row, "fov_deg", where) if row.get("fov_deg", "").strip() else DEFAULT_FOV_DEG)
    lat, lon, alt = (_number(row, c, where) for c in ("lat_cam", "lon_cam", "alt_cam"))
    yaw, pitch, roll = (_number(row, c, where) for c in ("yaw", "pitch", "roll"))
    exact_filled = [bool(row.get(c, "").strip()) for c in EXACT_CORNER_COLUMNS] if use_exact else [False]
    if any(exact_filled) and not all(exact_filled):
        empty = EXACT_CORNER_COLUMNS[exact_filled.index(False)]
        raise ValueError(f"{where}: field {empty!r} = {row.get(empty, '')!r} is empty while other exact corner "
                         f"columns of the row are filled")
    corner_cols = EXACT_CORNER_COLUMNS if all(exact_filled) else CORNER_COLUMNS
    uv = np.array([_number(row, c, where) for c in corner_cols]).reshape(4, 2)
    labels = uv if corner_cols is CORNER_COLUMNS else np.array(
        [_number(row, c, where) for c in CORNER_COLUMNS]).reshape(4, 2)

    airport = row.get("airport", "").strip().upper()
    if airport not in db:
        raise ValueError(f"{where}: field 'airport' = {row.get('airport')!r} is not in the runway DB {db_file}")
    found = db[airport].get(normalize_runway(row.get("runway", "")))
    if found is None:
        raise ValueError(f"{where}: field 'runway' = {row.get('runway')!r} is not a runway of {airport} in the "
                         f"runway DB {db_file} (has {', '.join(k for k, _ in db[airport].values())})")
    db_key, entry = found
    if (airport, db_key) not in frames:
        frames[(airport, db_key)] = _runway_frame(entry, airport, db_key, db_file)
    frame, corners_3d = frames[(airport, db_key)]

    path = resolve_within(base, image_text, context=f"{where}: field 'image'")
    K = intrinsics(w, h, fov)
    position = frame.to_runway(lat, lon, alt)
    R = frame.camera_rotation(yaw, pitch, roll)
    derived = approach_metrics(position, corners_3d)
    if not (np.isfinite(position).all() and np.isfinite(K).all() and all(map(math.isfinite, derived.values()))):
        raise ValueError(f"{where}: fields 'lat_cam', 'lon_cam', 'alt_cam' = {row['lat_cam']!r}, {row['lon_cam']!r}, "
                         f"{row['alt_cam']!r} give a non-finite camera geometry")
    slant_m = derived["slant_distance"] * METRES_PER_NM
    check = {}
    for field in DERIVED_COLUMNS:
        if row.get(field, "").strip():
            stored = _number(row, field, where)
            if abs(stored - derived[field]) > metrics_tolerance(field, slant_m):
                check[field] = (stored, derived[field])
    with np.errstate(all="ignore"):
        projected = project(corners_3d, R, position, K)
    exact = corner_cols is EXACT_CORNER_COLUMNS
    check.update(_corner_check(uv, corner_cols, projected, K, EXACT_TOL_PX if exact else LABEL_TOL_PX))
    if exact:
        for k, name in enumerate(CORNER_COLUMNS):
            stored, value = float(labels.reshape(-1)[k]), float(uv.reshape(-1)[k])
            if not abs(stored - value) < 1.0 + 1e-6:  # the label is the exact value truncated
                check[name] = (stored, value)

    meta = dict(row)
    meta.update(
        airport=airport, runway=row.get("runway", "").strip(), runway_db_key=db_key,
        runway_azimuth_deg=frame.azimuth_deg, runway_heading_deg=frame.heading_deg,
        yaw=yaw, pitch=pitch, roll=roll, fov_deg=fov, derived=derived, lard_check=check,
        corners_exact=exact, row=i, csv=str(csv_file),
    )
    return Sample(
        id=PurePosixPath(image_text.replace("\\", "/")).as_posix(),
        K=K,
        corners_3d=corners_3d,
        corners_2d=uv,
        position=position,
        width=w,
        height=h,
        R=R,
        image_path=path,
        meta=meta,
        _loader=_ImageLoader(path, where, PurePosixPath(image_text.replace("\\", "/")).as_posix()),
    )


@dataclass(frozen=True)
class _ImageLoader:
    """Loads one LARD row's image; a module-level class (not a closure) so that a sample pickles into a worker
    process of a local or Ray run."""

    path: Path
    where: str
    #: The image as the CSV names it (relative to the dataset root): what a message about it shows, never the
    #: absolute path.
    name: str = ""

    def __call__(self) -> np.ndarray:
        shown = self.name or str(self.path)
        try:
            return load_rgb(self.path)
        except FileNotFoundError:
            raise FileNotFoundError(f"{shown}: image file not found") from None
        except ValueError as exc:
            raise ValueError(str(exc).replace(str(self.path), shown)) from None


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
