"""Writing samples as a LARD V2 dataset (images, ``;``-separated metadata CSV, runway DB JSON).

See :mod:`.lard` for the format. What is written, and why:

- all LARD V2 columns in LARD units (NM, ft, ``pitch`` = 90 + pitch, …), floats with 6 decimals except
  ``lat_cam``/``lon_cam`` (10 decimals: 1e-6° is 0.1 m, too coarse for a sub-millimetre position round trip);
- the corner labels ``x_TR … y_BR`` truncated to integers exactly as the LARD labeller does (``int()``), so that
  tools built for LARD see LARD labels; the exact float projections go to ``x_TR_exact … y_BR_exact`` (full
  precision) and :func:`.lard_read.read_lard` prefers them, so our own ground truth stays exact;
- ``fov_deg`` (extension): the horizontal field of view of ``sample.K``, used by the reader unless overridden;
- ``reference`` (extension): free text naming the synthetic airport/generator, repeated on every row;
- ``sequence_id``, ``frame_index``, ``time_s`` (extension, :data:`.lard.SEQUENCE_COLUMNS`): written when the
  samples are frames of approach sequences (``meta`` has these keys: all samples or none), see :mod:`.sequence`.

The camera ``lat_cam/lon_cam/alt_cam`` come from ``sample.position`` and ``yaw/pitch/roll`` from ``sample.R``
through the :class:`~vbl_robust.geometry.geodesy.RunwayFrame` of the runway named by ``sample.meta["airport"]`` /
``sample.meta["runway"]`` in ``runway_db`` (entries built with
:func:`~vbl_robust.geometry.geodesy.runway_db_entry`).
"""

from __future__ import annotations

import csv
import json
import logging
import math
import re
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from ..geometry.geodesy import RunwayFrame
from .lard import (
    CORNER_COLUMNS,
    EXACT_CORNER_COLUMNS,
    LARD_COLUMNS,
    SEQUENCE_COLUMNS,
    approach_metrics,
    normalize_runway,
    truncated_labels,
)
from .sample import Sample

logger = logging.getLogger(__name__)

OUTPUT_COLUMNS = (*LARD_COLUMNS, *EXACT_CORNER_COLUMNS, "fov_deg", "reference")
IMAGE_FORMATS = ("png", "jpg", "jpeg")
_TEXT_DEFAULTS = {"type": "synthetic", "original_dataset": "vbl_robust", "time_to_landing": "", "weather": "",
                  "night": "", "time": "", "watermark_height": "0", "runway_in_cone": "UNKNOWN"}


def write_lard(
    out_dir: str | Path,
    samples: Iterable[Sample],
    runway_db: Mapping[str, Mapping[str, Mapping]],
    *,
    reference: str | None = None,
    image_format: str = "png",
    csv_name: str = "metadata.csv",
    db_name: str = "runways_db.json",
) -> Path:
    """Write ``samples`` as a LARD V2 dataset under ``out_dir`` and return the metadata CSV path.

    Layout: ``out_dir/images/<id>.<image_format>`` (RGB uint8 ``sample.image``), ``out_dir/<csv_name>``
    (image paths relative to it) and ``out_dir/<db_name>`` (``runway_db`` as given, LARD schema).

    Args:
        out_dir: output directory (created if needed).
        samples: samples with ``meta["airport"]``, ``meta["runway"]``, pixels, ``R`` (or LARD ``yaw``, ``pitch``,
            ``roll`` in ``meta``) and LARD intrinsics (square pixels, principal point at the image centre).
        runway_db: ``airport → runway → {"A".."D": {"coordinate", "position"}}`` containing every runway used.
        reference: text stored in the ``reference`` column (default: names the generator and DB file).
        image_format: ``"png"`` (lossless, default) or ``"jpg"``.

    Raises:
        ValueError: unknown format, a sample without airport/runway/pixels/attitude, a runway missing from
            ``runway_db``, corners that disagree with the DB runway (> 1 mm), non-LARD intrinsics, corners that
            do not project (behind the camera), duplicate sample ids, or sequence fields on some samples only
            (or a non-integer ``frame_index`` / non-finite ``time_s``).
    """
    import cv2

    fmt = image_format.lower().lstrip(".")
    if fmt not in IMAGE_FORMATS:
        raise ValueError(f"write_lard: image_format must be one of {IMAGE_FORMATS}, got {image_format!r}")
    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    db_index = _index_db(runway_db)
    if reference is None:
        reference = f"synthetic dataset written by vbl_robust; runway DB {db_name}"

    frames: dict[tuple[str, str], RunwayFrame] = {}
    names: set[str] = set()
    rows = []
    for sample in samples:
        airport, runway, entry = _runway_of(sample, db_index)
        frame = frames.get((airport, runway))
        if frame is None:
            frame = frames[(airport, runway)] = RunwayFrame.from_corners(entry)
        name = _image_name(sample.id, fmt, names)
        img = _pixels(sample)
        if not cv2.imwrite(str(out / "images" / name), np.ascontiguousarray(img[:, :, ::-1])):
            raise ValueError(f"write_lard: sample {sample.id}: OpenCV could not write {out / 'images' / name}")
        rows.append(_row(sample, frame, airport, runway, f"images/{name}", reference))

    in_sequence = ["sequence_id" in r for r in rows]
    if any(in_sequence) and not all(in_sequence):
        with_id, without = rows[in_sequence.index(True)], rows[in_sequence.index(False)]
        raise ValueError(f"write_lard: image {without['image']!r} has no meta 'sequence_id' but image "
                         f"{with_id['image']!r} has one: either every sample belongs to a sequence or none does")
    columns = (*OUTPUT_COLUMNS, *SEQUENCE_COLUMNS) if any(in_sequence) else OUTPUT_COLUMNS
    csv_path = out / csv_name
    with open(csv_path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=columns, delimiter=";", lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    (out / db_name).write_text(json.dumps(runway_db, indent=4) + "\n", encoding="utf-8")
    logger.info("wrote %d LARD rows to %s", len(rows), csv_path)
    return csv_path


def _index_db(runway_db: Mapping) -> dict[str, dict[str, tuple[str, Mapping]]]:
    index: dict[str, dict[str, tuple[str, Mapping]]] = {}
    for airport, runways in runway_db.items():
        index[str(airport).strip().upper()] = {normalize_runway(k): (str(k), v) for k, v in runways.items()}
    return index


def _runway_of(sample: Sample, db_index) -> tuple[str, str, Mapping]:
    meta = sample.meta or {}
    if "airport" not in meta or "runway" not in meta:
        raise ValueError(f"write_lard: sample {sample.id}: meta must name 'airport' and 'runway' "
                         f"(got keys {sorted(meta)})")
    airport = str(meta["airport"]).strip().upper()
    runways = db_index.get(airport)
    if runways is None:
        raise ValueError(f"write_lard: sample {sample.id}: airport {meta['airport']!r} is not in runway_db "
                         f"(has {sorted(db_index)})")
    found = runways.get(normalize_runway(meta["runway"]))
    if found is None:
        raise ValueError(f"write_lard: sample {sample.id}: runway {meta['runway']!r} of {airport} is not in "
                         f"runway_db (has {sorted(k for k, _ in runways.values())})")
    return airport, found[0], found[1]


def _image_name(sample_id: str, fmt: str, taken: set[str]) -> str:
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(str(sample_id)).with_suffix("").as_posix()).strip("._") or "image"
    name = f"{stem}.{fmt}"
    if name in taken:
        raise ValueError(f"write_lard: duplicate sample id {sample_id!r} (image name {name!r} already used)")
    taken.add(name)
    return name


def _pixels(sample: Sample) -> np.ndarray:
    img = np.asarray(sample.image)
    if img.dtype != np.uint8 or img.shape != (sample.height, sample.width, 3):
        raise ValueError(f"write_lard: sample {sample.id}: image must be ({sample.height}, {sample.width}, 3) "
                         f"uint8 RGB, got {img.shape} {img.dtype}")
    return img


def _fov_deg(sample: Sample) -> float:
    K = sample.K
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    if not (math.isclose(K[1, 1], f, rel_tol=1e-9) and math.isclose(cx, sample.width / 2, abs_tol=1e-9)
            and math.isclose(cy, sample.height / 2, abs_tol=1e-9) and K[0, 1] == 0.0):
        raise ValueError(f"write_lard: sample {sample.id}: K must be a LARD camera (fx = fy, no skew, principal "
                         f"point at the image centre), got {K.tolist()}")
    return math.degrees(2.0 * math.atan(sample.width / 2 / f))


def _attitude(sample: Sample, frame: RunwayFrame) -> tuple[float, float, float]:
    if sample.R is not None:
        return frame.camera_attitude(sample.R)
    try:
        return float(sample.meta["yaw"]), float(sample.meta["pitch"]), float(sample.meta["roll"])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"write_lard: sample {sample.id}: no rotation R and no numeric LARD yaw/pitch/roll "
                         f"in meta") from None


def _row(sample: Sample, frame: RunwayFrame, airport: str, runway: str, image: str, reference: str) -> dict:
    gap = float(np.max(np.abs(frame.corners_3d - sample.corners_3d)))
    if gap > 1e-3:
        raise ValueError(f"write_lard: sample {sample.id}: corners_3d differ from runway_db {airport}/{runway} "
                         f"by {gap:.3f} m (build the DB entry with geometry.runway_db_entry for this runway)")
    uv = sample.corners_2d
    if not np.all(np.isfinite(uv)):
        raise ValueError(f"write_lard: sample {sample.id}: corners_2d not finite (runway behind the camera?)")
    lat, lon, alt = (float(v) for v in frame.to_geodetic(sample.position))
    yaw, pitch, roll = _attitude(sample, frame)
    meta = sample.meta or {}
    row = {k: str(meta.get(k, default)) for k, default in _TEXT_DEFAULTS.items()}
    row.update({
        "uuid": str(uuid.uuid5(uuid.NAMESPACE_URL, f"vbl_robust:{sample.id}")),
        "image": image, "height": str(sample.height), "width": str(sample.width),
        "scenario": str(meta.get("scenario", f"{airport}-{runway}")), "airport": airport, "runway": runway,
        "lat_cam": f"{lat:.10f}", "lon_cam": f"{lon:.10f}", "alt_cam": f"{alt:.6f}",
        "yaw": f"{yaw:.6f}", "pitch": f"{pitch:.6f}", "roll": f"{roll:.6f}",
        "fov_deg": f"{_fov_deg(sample):.10f}", "reference": reference,
    })
    row.update({k: f"{v:.6f}" for k, v in approach_metrics(sample.position, sample.corners_3d).items()})
    flat = uv.reshape(-1)  # TR(u, v), TL(u, v), BL(u, v), BR(u, v) = the column order
    row.update({c: str(int(v)) for c, v in zip(CORNER_COLUMNS, truncated_labels(flat), strict=True)})
    row.update({c: repr(float(v)) for c, v in zip(EXACT_CORNER_COLUMNS, flat, strict=True)})
    if "sequence_id" in meta:
        row.update(_sequence_fields(sample, meta))
    return row


def _sequence_fields(sample: Sample, meta: Mapping) -> dict[str, str]:
    seq = str(meta["sequence_id"]).strip()
    frame, time_s = meta.get("frame_index"), meta.get("time_s")
    if not seq:
        raise ValueError(f"write_lard: sample {sample.id}: meta 'sequence_id' is empty")
    if isinstance(frame, bool) or not isinstance(frame, int | np.integer) or frame < 0:
        raise ValueError(f"write_lard: sample {sample.id}: meta 'frame_index' = {frame!r} is not an integer >= 0")
    if isinstance(time_s, bool) or not isinstance(time_s, int | float | np.number) or not math.isfinite(time_s):
        raise ValueError(f"write_lard: sample {sample.id}: meta 'time_s' = {time_s!r} is not a finite number")
    return {"sequence_id": seq, "frame_index": str(int(frame)), "time_s": f"{float(time_s):.6f}"}
