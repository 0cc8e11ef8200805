"""The LARD V2 dataset format: columns, units, runway database and derived approach quantities.

Shared by :mod:`.lard_read` (``read_lard``) and :mod:`.lard_write` (``write_lard``), so that one reader serves
real LARD V2 data and the synthetic scenes of this package.

Metadata CSV (``;``-separated, read by column name)
    ``lat_cam, lon_cam`` degrees, ``alt_cam`` metres (runway-DB datum); ``yaw`` true heading in degrees,
    ``pitch`` stored as 90 + aeronautical pitch, ``roll`` degrees (right wing down > 0), see
    :mod:`vbl_robust.geometry.geodesy` for how they map to the camera rotation. ``slant_distance`` and
    ``along_track_distance`` in nautical miles (1852 m), ``height_above_runway`` in feet (3.28084 ft/m), path
    angles in degrees. Corner labels ``x_TR … y_BR`` are integer-truncated pixels (``int()``, towards zero).

Extensions written by this package (ignored by LARD tools, which read by name)
    ``x_TR_exact … y_BR_exact``: the exact float corner projections (full precision), preferred by the reader;
    ``reference``: free text naming the synthetic airport / generator;
    ``sequence_id, frame_index, time_s`` (approach sequences only, :mod:`.sequence`): the sequence a frame belongs
    to, its 0-based index along the approach and its time in seconds since the sequence's first frame.

Runway database (JSON)
    ``ICAO → runway → A|B|C|D → {"position": {x, y, z}, "coordinate": {latitude, longitude, altitude}}``,
    ``position`` in ECEF on the LARD sphere. Runway keys are not zero-padded consistently ("2" vs "02"): they
    are matched through :func:`normalize_runway` ("02" → "2", "03r" → "3R").
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..geometry.camera import CORNER_NAMES

#: All LARD V2 metadata columns, in the order of the published V2 metadata.
LARD_COLUMNS = (
    "uuid", "image", "height", "width", "type", "original_dataset", "scenario", "airport", "runway",
    "time_to_landing", "weather", "night", "time", "lat_cam", "lon_cam", "alt_cam", "yaw", "pitch", "roll",
    "slant_distance", "along_track_distance", "height_above_runway", "lateral_path_angle", "vertical_path_angle",
    "watermark_height", "runway_in_cone",
    *(f"{c}_{n}" for n in CORNER_NAMES for c in ("x", "y")),
)
CORNER_COLUMNS = tuple(f"{c}_{n}" for n in CORNER_NAMES for c in ("x", "y"))
EXACT_CORNER_COLUMNS = tuple(f"{name}_exact" for name in CORNER_COLUMNS)
#: Extension columns of approach sequences (written only for samples that belong to one, see :mod:`.sequence`).
SEQUENCE_COLUMNS = ("sequence_id", "frame_index", "time_s")
#: Columns the reader cannot do without.
REQUIRED_COLUMNS = (
    "image", "width", "height", "airport", "runway", "lat_cam", "lon_cam", "alt_cam", "yaw", "pitch", "roll",
    *CORNER_COLUMNS,
)
#: Derived columns: computed by the reader when absent, cross-checked when present.
DERIVED_COLUMNS = (
    "slant_distance", "along_track_distance", "height_above_runway", "lateral_path_angle", "vertical_path_angle",
)

METRES_PER_NM = 1852.0
FEET_PER_METRE = 3.28084  # the factor the LARD labeller uses
GLIDE_PATH_ANCHOR_M = 305.0  # vertical path angle is measured from this point past the LTP (LARD V2)

_RUNWAY_RE = re.compile(r"^0*(\d{1,2})([A-Z]*)$")


def normalize_runway(key) -> str:
    """Canonical runway designator: upper case, no zero padding (``"02"`` → ``"2"``, ``"03r"`` → ``"3R"``)."""
    text = str(key).strip().upper()
    m = _RUNWAY_RE.match(text)
    if m is None:
        return text
    return f"{int(m.group(1))}{m.group(2)}"


#: Plausible camera and runway altitudes, metres (the lowest airport is about −400 m, none is above 4.5 km).
ALTITUDE_RANGE_M = (-1000.0, 100_000.0)


def load_runway_db(path: str | Path) -> dict[str, dict[str, tuple[str, dict]]]:
    """Read a LARD runway DB: ``{AIRPORT: {normalised runway: (key as stored, corner entry)}}``.

    Every corner is checked: ``coordinate`` with finite numeric ``latitude`` in (−90, 90), ``longitude`` in
    [−180, 180], ``altitude`` in :data:`ALTITUDE_RANGE_M`; ``position`` (ECEF, not used by the reader), when
    present, with finite numeric ``x, y, z``.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: not UTF-8 JSON, or not shaped ``airport → runway → {A, B, C, D}``, or a corner value missing,
            not a number or out of range, or two airports/runways with the same normalised name (one line naming
            the file, the airport, the runway, the corner, the field and the value).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: runway DB file not found")
    try:
        raw = json.loads(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{p}: runway DB is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, the int-digits limit, absurd nesting
        raise ValueError(f"{p}: malformed runway DB JSON ({_one_line(exc)})") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{p}: runway DB must be a JSON object airport → runway → corners, got {type(raw).__name__}")
    db: dict[str, dict[str, tuple[str, dict]]] = {}
    stored_airport: dict[str, str] = {}
    for airport, runways in raw.items():
        name = str(airport).strip().upper()
        if not name:
            raise ValueError(f"{p}: airport {airport!r}: empty airport name")
        if name in db:
            raise ValueError(f"{p}: airports {stored_airport[name]!r} and {airport!r} are the same airport {name!r}")
        if not isinstance(runways, dict):
            raise ValueError(f"{p}: airport {airport!r}: expected an object of runways, got {type(runways).__name__}")
        table: dict[str, tuple[str, dict]] = {}
        for key, entry in runways.items():
            if not isinstance(entry, dict) or any(c not in entry for c in "ABCD"):
                raise ValueError(f"{p}: airport {airport!r} runway {key!r}: expected corners A, B, C, D")
            norm = normalize_runway(key)
            if not norm:
                raise ValueError(f"{p}: airport {airport!r} runway {key!r}: empty runway designator")
            if norm in table:
                raise ValueError(f"{p}: airport {airport!r}: runways {table[norm][0]!r} and {key!r} are the same "
                                 f"designator {norm!r}")
            for corner in "ABCD":
                _check_corner(entry[corner], f"{p}: airport {airport!r} runway {key!r} corner {corner!r}")
            table[norm] = (str(key), entry)
        db[name] = table
        stored_airport[name] = str(airport)
    return db


_COORDINATE_RANGES = {
    "latitude": (-90.0, 90.0, False),  # (low, high, inclusive)
    "longitude": (-180.0, 180.0, True),
    "altitude": (*ALTITUDE_RANGE_M, True),
}


def _check_corner(corner, where: str) -> None:
    if not isinstance(corner, dict) or not isinstance(corner.get("coordinate"), dict):
        raise ValueError(f"{where}: expected {{'coordinate': {{latitude, longitude, altitude}}, 'position': "
                         f"{{x, y, z}}}}, got {_short(corner)}")
    for field, (lo, hi, inclusive) in _COORDINATE_RANGES.items():
        value = _db_number(corner["coordinate"], field, f"{where}: field 'coordinate.{field}'")
        inside = lo <= value <= hi if inclusive else lo < value < hi
        if not inside:
            interval = f"[{lo:g}, {hi:g}]" if inclusive else f"({lo:g}, {hi:g})"
            raise ValueError(f"{where}: field 'coordinate.{field}' = {corner['coordinate'][field]!r} is not in "
                             f"{interval}")
    if "position" in corner:
        if not isinstance(corner["position"], dict):
            raise ValueError(f"{where}: field 'position' = {_short(corner['position'])} is not an object {{x, y, z}}")
        for axis in "xyz":
            _db_number(corner["position"], axis, f"{where}: field 'position.{axis}'")


def _db_number(obj: dict, field: str, where: str) -> float:
    if field not in obj:
        raise ValueError(f"{where} is missing")
    value = obj[field]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{where} = {_short(value)} is not a number")
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    if not math.isfinite(number):
        raise ValueError(f"{where} = {_short(value)} is not a finite number")
    return number


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}… ({type(value).__name__})"


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def truncated_labels(corners_2d: np.ndarray) -> np.ndarray:
    """Corner pixels as the LARD labeller stores them: truncated towards zero (``int()``), as float."""
    return np.trunc(np.asarray(corners_2d, dtype=np.float64))


def approach_metrics(position: np.ndarray, corners_3d: np.ndarray) -> dict[str, float]:
    """LARD V2 derived quantities of a camera position, in LARD units, computed as the V2 labeller does.

    The runway axes are ``x = unit(FPAP − LTP)`` (follows the runway slope), ``y = unit(BL − LTP)``,
    ``z = x × y``; the LTP is the runway-frame origin. ``along_track_distance = |C·x|``, ``height_above_runway =
    C_z`` (vertical of the runway frame); the lateral path angle is the angle between −x and the camera
    direction seen from the LTP projected on the runway plane (negative when the aircraft is left of the
    centreline); the vertical path angle is the elevation of the camera above the runway plane seen from the
    point 305 m past the LTP (positive above).

    Args:
        position: (3,) camera position in the runway frame, metres.
        corners_3d: (4, 3) runway corners TR, TL, BL, BR in the runway frame, metres.

    Returns:
        ``{"slant_distance": NM, "along_track_distance": NM, "height_above_runway": ft,
        "lateral_path_angle": deg, "vertical_path_angle": deg}``.
    """
    c = np.asarray(position, dtype=np.float64).reshape(3)
    k = np.asarray(corners_3d, dtype=np.float64).reshape(4, 3)
    ltp = 0.5 * (k[2] + k[3])
    fpap = 0.5 * (k[0] + k[1])
    x = (fpap - ltp) / np.linalg.norm(fpap - ltp)
    y = (k[2] - ltp) / np.linalg.norm(k[2] - ltp)
    z = np.array([x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]])
    basis = np.stack([x, y, z])

    rel = c - ltp
    local = basis @ rel
    flat = np.array([local[0], local[1], 0.0])
    lateral = _angle(flat, np.array([-1.0, 0.0, 0.0]))
    if flat[1] > 0:
        lateral = -lateral
    v = basis @ (c - (ltp + GLIDE_PATH_ANCHOR_M * x))
    vertical = _angle(v, np.array([v[0], v[1], 0.0]))
    if v[2] < 0:
        vertical = -vertical
    return {
        "slant_distance": float(np.linalg.norm(rel)) / METRES_PER_NM,
        "along_track_distance": abs(float(local[0])) / METRES_PER_NM,
        "height_above_runway": float(c[2]) * FEET_PER_METRE,
        "lateral_path_angle": lateral,
        "vertical_path_angle": vertical,
    }


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0.0 or nb == 0.0:
        return 0.0
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b) / (na * nb)))))


def metrics_tolerance(field: str, slant_m: float) -> float:
    """Agreement tolerance (LARD units) between a stored and a recomputed derived value.

    The LARD labeller measures horizontal distances along WGS84 geodesics and heights as altitude differences;
    this package uses the LARD sphere. At ``slant_m`` metres they differ by up to ~0.5 % in distance and by the
    Earth-curvature drop ``d²/2R`` in height, plus the 6-decimal rounding of the CSV.
    """
    curvature_m = slant_m**2 / (2 * 6_371_010.0)
    if field in ("slant_distance", "along_track_distance"):
        return (5.0 + 0.005 * slant_m) / METRES_PER_NM
    if field == "height_above_runway":
        return (2.0 + 1.5 * curvature_m + 0.002 * slant_m) * FEET_PER_METRE
    return 0.1 + math.degrees((2.0 + 1.5 * curvature_m) / max(slant_m, 1.0))  # path angles, degrees
