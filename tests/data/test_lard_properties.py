"""Properties of the LARD V2 reader (hypothesis): valid datasets written by ``write_lard`` are corrupted at
random (CSV fields, columns, rows, raw bytes; runway DB entries) and read back.

The contract (``vbl_robust.data.lard_read`` module docstring): bad input never crashes and never passes
silently. A user mistake is a one-line ``ValueError`` naming the file, the row, the field and the value; an
inconsistency between fields is recorded in ``sample.meta["lard_check"]``; no other exception type escapes,
and no image path outside the dataset root is accepted.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import re
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st
from lard_helpers import make_runway_db, make_samples

from vbl_robust.data.lard import (
    CORNER_COLUMNS,
    DERIVED_COLUMNS,
    EXACT_CORNER_COLUMNS,
    REQUIRED_COLUMNS,
    approach_metrics,
    metrics_tolerance,
    normalize_runway,
)
from vbl_robust.data.lard_read import (
    EXACT_TOL_PX,
    FIELD_RANGES,
    LABEL_TOL_PX,
    MAX_IMAGE_SIZE_PX,
    RELATIVE_TOL_PX,
    RUNWAY_IN_CONE,
    read_lard,
)
from vbl_robust.data.lard_write import write_lard
from vbl_robust.data.paths import resolve_within
from vbl_robust.geometry.camera import project

# deterministic in CI, no example database written into the shared working tree
PROPS = settings(max_examples=80, deadline=None, derandomize=True, database=None)

#: Columns the reader parses as numbers.
NUMERIC = ("width", "height", "lat_cam", "lon_cam", "alt_cam", "yaw", "pitch", "roll", *CORNER_COLUMNS,
           *EXACT_CORNER_COLUMNS, *DERIVED_COLUMNS, "fov_deg")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A written dataset: its directory, the CSV header and rows (lists of text), and the runway DB (dict)."""
    root = tmp_path_factory.mktemp("lard_props") / "ds"
    db = make_runway_db()
    csv_path = write_lard(root, make_samples(db, n=3), db)
    with open(csv_path, newline="", encoding="utf-8") as f:
        table = list(csv.reader(f, delimiter=";"))
    (root / "images" / "link_out").symlink_to(root.parent, target_is_directory=True)
    return {"root": root, "header": table[0], "rows": table[1:], "db": json.loads((root / "runways_db.json").read_text())}


def to_text(header, rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, delimiter=";", lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


_BASE = object()


def read(base, csv_text: str | bytes | None = None, db: object = _BASE, db_text: str | None = None, **options):
    """Write the case files into the dataset root and read them: (samples or the ValueError, csv path, db path)."""
    root = base["root"]
    csv_path, db_path = root / "case.csv", root / "case_db.json"
    data = csv_text if csv_text is not None else to_text(base["header"], base["rows"])
    csv_path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
    if db_text is None:
        db_text = json.dumps(base["db"] if db is _BASE else db)
    db_path.write_text(db_text, encoding="utf-8")
    try:
        return read_lard(csv_path, db_path, **options), csv_path, db_path
    except ValueError as exc:  # any other exception type fails the test
        msg = str(exc)
        assert "\n" not in msg, msg
        return exc, csv_path, db_path


def assert_sound(samples, root: Path):
    """Every accepted sample is finite, confined to the root, and consistent with its labels or flagged."""
    base_dir = root.resolve()
    for s in samples:
        for a in (s.K, s.corners_3d, s.corners_2d, s.position, s.R):
            assert np.isfinite(a).all(), s.id
        np.testing.assert_allclose(s.R @ s.R.T, np.eye(3), atol=1e-9)
        assert s.image_path.is_relative_to(base_dir) and s.image_path != base_dir
        assert ".." not in PurePosixPath(s.id).parts and not PurePosixPath(s.id).is_absolute()
        assert 0 < s.width <= MAX_IMAGE_SIZE_PX and 0 < s.height <= MAX_IMAGE_SIZE_PX
        if not s.meta["lard_check"]:
            assert consistent(s), (s.id, s.meta)


def consistent(s) -> bool:
    """Recomputed from the returned sample: its corners reproject onto its labels, its derived values agree."""
    proj = project(s.corners_3d, s.R, s.position, s.K)
    tol = EXACT_TOL_PX if s.meta["corners_exact"] else LABEL_TOL_PX
    for k in range(4):
        if np.isfinite(proj[k]).all():
            t = tol + RELATIVE_TOL_PX * np.linalg.norm(proj[k] - s.K[:2, 2])
            if np.abs(proj[k] - s.corners_2d[k]).max() > t:
                return False
    derived = approach_metrics(s.position, s.corners_3d)
    slant = derived["slant_distance"] * 1852.0
    return all(abs(float(s.meta[f]) - derived[f]) <= metrics_tolerance(f, slant)
               for f in DERIVED_COLUMNS if s.meta.get(f, "").strip())


def names_row(msg: str, csv_path: Path, row: int) -> bool:
    return str(csv_path) in msg and f"row {row}" in msg


# -- values --------------------------------------------------------------------------------------------------
numeric_text = st.one_of(
    st.floats().map(repr),
    st.floats(-1e6, 1e6).map(lambda v: f"{v:.6f}"),
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["", " ", "nan", "NaN", "-inf", "Infinity", "1e400", "-1e400", "1,5", "0x10", "1e", "--1",
                     " 12 ", "1024", "1024.0", "1024.5", "0", "-0", "90", "-90", "180", "-180", "360", "400",
                     "1e5", "100001"]),
)
path_text = st.one_of(
    st.sampled_from(["../x.png", "/etc/passwd", "C:\\x.png", "C:x.png", "\\\\srv\\share\\x.png", "images/../../x.png",
                     ".", "./", "images/./scene_000.png", "a/../b.png", "images\\scene_001.png", "~/x.png",
                     "images/link_out/x.png", "images/link_out/ds/images/scene_000.png", "a\x00b.png", "a\nb.png",
                     "images", " images/scene_002.png "]),
    st.text(max_size=16),
)
free_text = st.text(max_size=24)


def documented_number(field: str, text: str) -> bool:
    """Whether the reader's documented rules accept ``text`` for ``field`` (an empty optional field included)."""
    t = text.strip()
    if not t and field in (*DERIVED_COLUMNS, "fov_deg"):
        return True  # absent: computed / default
    try:
        v = float(t)
    except ValueError:
        return False
    if not math.isfinite(v):
        return False
    if field in ("width", "height"):
        return 0 < v <= MAX_IMAGE_SIZE_PX and v == int(v)
    if field in FIELD_RANGES:
        lo, hi, inclusive = FIELD_RANGES[field]
        return lo <= v <= hi if inclusive else lo < v < hi
    return True


@PROPS
@given(st.data(), st.integers(0, 2), st.booleans(), st.booleans())
def test_a_corrupted_field_is_rejected_by_name_or_read_soundly(base, data, r, target_only, odd_only):
    header = base["header"]
    field = data.draw(st.sampled_from(header), label="field")
    if field in NUMERIC:
        value = data.draw(numeric_text, label="value")
    elif field == "image":
        value = data.draw(path_text, label="value")
    elif field == "runway_in_cone":
        value = data.draw(st.one_of(st.sampled_from(RUNWAY_IN_CONE), free_text), label="value")
    else:
        value = data.draw(free_text, label="value")
    rows = copy.deepcopy(base["rows"])
    rows[r][header.index(field)] = value
    out, csv_path, _ = read(base, to_text(header, rows), target_runway_only=target_only, in_odd_only=odd_only)
    row = r + 1
    event(f"{type(out).__name__ if isinstance(out, ValueError) else 'accepted'}")

    if isinstance(out, ValueError):
        msg = str(out)
        assert names_row(msg, csv_path, row), msg
        if field in NUMERIC:
            assert not documented_number(field, value), msg  # a valid number is never refused
            assert f"'{field}'" in msg and repr(value) in msg, msg
        elif field == "image":
            assert "'image'" in msg, msg
        elif field in ("airport", "runway"):
            assert "'airport'" in msg or "'runway'" in msg, msg
        elif field == "runway_in_cone":
            assert odd_only and value.strip() not in RUNWAY_IN_CONE and repr(value) in msg, msg
        else:
            pytest.fail(f"free-text field {field!r} = {value!r} refused: {msg}")
        return

    samples = out
    assert_sound(samples, base["root"])
    if field in NUMERIC:
        assert documented_number(field, value), f"{field} = {value!r} accepted"
    if field == "image":
        text = value.strip()
        resolved = (base["root"] / text.replace("\\", "/")).resolve()
        assert resolved.is_relative_to(base["root"].resolve()), value
    mine = [s for s in samples if s.meta["row"] == row]
    if mine:
        meta = mine[0].meta
        if field in ("yaw", "pitch", "roll"):
            assert meta[field] == float(value)  # the LARD angle as a float
        elif field == "fov_deg":
            assert meta[field] == (float(value) if value.strip() else 60.0)
        elif field in ("airport", "runway"):
            assert meta[field] == (value.strip().upper() if field == "airport" else value.strip())
        else:
            assert meta[field] == value  # text kept as written
    if not target_only and not odd_only:
        assert [s.meta["row"] for s in samples] == [1, 2, 3]  # nothing skipped


@PROPS
@given(st.data(), st.sampled_from(["drop", "duplicate", "extra", "short", "dup_row", "blank", "garbage", "bytes",
                                   "quote", "header_only", "empty"]))
def test_structural_corruptions_are_named_errors(base, data, kind):
    header, rows = list(base["header"]), copy.deepcopy(base["rows"])
    r = data.draw(st.integers(0, len(rows) - 1), label="row")
    text = None
    if kind == "drop":
        col = data.draw(st.sampled_from(header), label="column")
        k = header.index(col)
        header.pop(k)
        for row in rows:
            row.pop(k)
    elif kind == "duplicate":
        col = data.draw(st.sampled_from(header), label="column")
        header.append(col)
        for row in rows:
            row.append(row[base["header"].index(col)])
    elif kind == "extra":
        rows[r].append(data.draw(free_text, label="extra"))
    elif kind == "short":
        rows[r] = rows[r][: data.draw(st.integers(1, len(header) - 1), label="keep")]
    elif kind == "dup_row":
        rows.insert(data.draw(st.integers(r + 1, len(rows)), label="at"), list(rows[r]))
    elif kind == "header_only":
        rows = []
    lines = to_text(header, rows).splitlines(keepends=True)
    if kind == "blank":
        lines.insert(data.draw(st.integers(1, len(lines)), label="at"), "\n")
    elif kind == "garbage":
        lines.insert(data.draw(st.integers(1, len(lines)), label="at"),
                     data.draw(st.text(min_size=1, max_size=40).filter(lambda t: t.strip()), label="garbage") + "\n")
    elif kind == "quote":
        line = lines[r + 1]
        at = data.draw(st.integers(0, len(line) - 1), label="at")
        lines[r + 1] = line[:at] + data.draw(st.sampled_from(['"', ';', '";', '\r']), label="char") + line[at:]
    elif kind == "empty":
        lines = []
    text = "".join(lines).encode("utf-8")
    if kind == "bytes":
        at = data.draw(st.integers(0, len(text)), label="at")
        text = text[:at] + data.draw(st.sampled_from([b"\xff", b"\xc3", b"\xe9t\xe9", b"\x80\x80"]), label="bytes") + text[at:]

    out, csv_path, _ = read(base, text, target_runway_only=data.draw(st.booleans(), label="target_only"))
    event(f"{kind}: {'ValueError' if isinstance(out, ValueError) else 'accepted'}")
    if not isinstance(out, ValueError):
        assert_sound(out, base["root"])
        assert kind in ("drop", "blank", "header_only", "garbage", "quote"), kind
        if kind == "drop":
            assert col not in REQUIRED_COLUMNS and len(out) == 3
            assert all(s.meta["corners_exact"] is (col not in EXACT_CORNER_COLUMNS) for s in out)
        if kind == "blank":
            assert [s.meta["row"] for s in out] == [1, 2, 3]
        if kind == "header_only":
            assert out == []
        return
    msg = str(out)
    assert str(csv_path) in msg, msg
    if kind == "drop":
        assert col in REQUIRED_COLUMNS and f"missing column(s) {col}" in msg
    elif kind == "duplicate":
        assert f"column(s) {col} appear more than once" in msg
    elif kind in ("extra", "short"):
        assert f"row {r + 1} " in msg and "field(s), the header has" in msg, msg
    elif kind == "dup_row":
        assert "same image and runway" in msg and f"as row {r + 1}" in msg, msg
    elif kind == "bytes":
        # invalid bytes: refused as text, or the damaged field refused where it stands (its row or column named)
        assert re.search(r"not UTF-8|row \d+ |column\(s\) ", msg), msg
    elif kind == "empty":
        assert "missing column(s)" in msg
    else:
        assert kind in ("garbage", "quote"), (kind, msg)


# -- runway DB ---------------------------------------------------------------------------------------------
json_value = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.integers(10**308, 10**320) | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=6,
)


def finite_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and abs(v) < 1e308 and math.isfinite(v)


def db_documented_valid(db) -> bool:
    """The runway DB rules of ``load_runway_db``, written independently."""
    if not isinstance(db, dict):
        return False
    airports = [str(a).strip().upper() for a in db]
    if "" in airports or len(set(airports)) != len(airports):
        return False
    for runways in db.values():
        if not isinstance(runways, dict):
            return False
        keys = [normalize_runway(k) for k in runways]
        if "" in keys or len(set(keys)) != len(keys):
            return False
        for entry in runways.values():
            if not isinstance(entry, dict) or any(c not in entry for c in "ABCD"):
                return False
            for c in "ABCD":
                corner = entry[c]
                if not isinstance(corner, dict) or not isinstance(corner.get("coordinate"), dict):
                    return False
                coord = corner["coordinate"]
                if not all(finite_number(coord.get(f)) for f in ("latitude", "longitude", "altitude")):
                    return False
                if not (-90 < coord["latitude"] < 90 and -180 <= coord["longitude"] <= 180
                        and -1000 <= coord["altitude"] <= 100_000):
                    return False
                if "position" in corner:
                    p = corner["position"]
                    if not isinstance(p, dict):
                        return False
                    if not all(finite_number(p.get(f)) for f in "xyz"):
                        return False
    return True


@st.composite
def corrupted_db(draw, db):
    db = copy.deepcopy(db)
    airport = draw(st.sampled_from(sorted(db)))
    runway = draw(st.sampled_from(sorted(db[airport])))
    corner = draw(st.sampled_from("ABCD"))
    kind = draw(st.sampled_from(["leaf", "nudge", "delete", "replace", "dup_airport", "dup_runway", "top"]))
    entry = db[airport][runway]
    if kind in ("leaf", "nudge"):
        block = draw(st.sampled_from(["coordinate", "position"]))
        leaf = draw(st.sampled_from(["latitude", "longitude", "altitude"] if block == "coordinate" else "xyz"))
        if kind == "leaf":
            entry[corner][block][leaf] = draw(st.one_of(json_value, st.sampled_from(
                [math.nan, math.inf, -math.inf, 10**400, True, "1.0", 91.0, -90.0, 181.0, 200_000.0, None])))
        else:  # a plausible typo: the entry stays well formed
            entry[corner][block][leaf] += draw(st.floats(-1e-3, 1e-3) | st.floats(-50, 50))
    elif kind == "delete":
        path = draw(st.sampled_from([(corner,), (corner, "coordinate"), (corner, "position"),
                                     *((corner, "coordinate", f) for f in ("latitude", "longitude", "altitude")),
                                     *((corner, "position", f) for f in "xyz")]))
        obj = entry
        for p in path[:-1]:
            obj = obj[p]
        del obj[path[-1]]
    elif kind == "replace":
        target = draw(st.sampled_from(["runways", "entry", "corner", "coordinate"]))
        value = draw(json_value)
        if target == "runways":
            db[airport] = value
        elif target == "entry":
            db[airport][runway] = value
        elif target == "corner":
            entry[corner] = value
        else:
            entry[corner]["coordinate"] = value
    elif kind == "dup_airport":
        db[f" {airport.lower()}"] = copy.deepcopy(db[airport])
    elif kind == "dup_runway":
        entry_copy = copy.deepcopy(entry)
        db[airport][f"0{runway}" if not runway.startswith("0") else runway.lstrip("0")] = entry_copy
    else:
        db = draw(json_value)
    return db, airport, runway, kind


@PROPS
@given(st.data())
def test_a_corrupted_runway_db_is_rejected_by_name_or_read_soundly(base, data):
    db, airport, runway, kind = data.draw(corrupted_db(base["db"]))
    out, _, db_path = read(base, db=db, target_runway_only=False)
    event(f"{kind}: {'ValueError' if isinstance(out, ValueError) else 'accepted'}")
    if isinstance(out, ValueError):
        msg = str(out)
        assert str(db_path) in msg, msg
        # a runway that is in the DB as documented is never refused for the DB's sake
        assert not db_documented_valid(db) or re.search(r"degenerate runway corners|row \d+ ", msg), msg
        if kind in ("leaf", "delete") and not db_documented_valid(db):
            assert f"airport {airport!r}" in msg and f"runway {runway!r}" in msg, msg
        return
    assert db_documented_valid(db), ("accepted", kind, db if kind == "top" else db[airport])
    assert_sound(out, base["root"])
    assert len(out) == 3


@pytest.mark.parametrize("text", ["", "{", "[]", "null", '{"VBLA": 3}', "[" * 50_000 + "]" * 50_000,
                                  '{"VBLA": {"09": {"A": ' + "1" * 5000 + "}}}", '{"VBLA": {"09": NaN}}'])
def test_malformed_db_json_names_the_file(base, text):
    out, _, db_path = read(base, db_text=text)
    assert isinstance(out, ValueError) and str(db_path) in str(out)


# -- paths -----------------------------------------------------------------------------------------------------
path_chars = st.lists(st.sampled_from(list("ab./\\:~ \x00\n") + ["..", "C:", "link_out"]), max_size=12).map("".join)


@PROPS
@given(st.one_of(path_text, path_chars, st.lists(st.sampled_from(["a", ".", "..", "", "link_out", "b.png"]),
                                                 max_size=5).map("/".join)))
def test_resolve_within_never_leaves_the_root(base, text):
    root = base["root"] / "images"
    try:
        p = resolve_within(root, text, context="ctx")
    except ValueError as exc:
        assert str(exc).startswith("ctx: ") and "\n" not in str(exc)
        return
    assert p.is_relative_to(root.resolve()) and p != root.resolve()
    parts = text.strip().replace("\\", "/").split("/")
    assert ".." not in parts and not text.strip().startswith(("/", "\\")) and not PureWindowsPath(text.strip()).drive
    assert not any(ord(c) < 32 for c in text.strip())


# -- the examples these properties found (regressions) -----------------------------------------------------------
def _set(base, field, value, row=0):
    rows = copy.deepcopy(base["rows"])
    rows[row][base["header"].index(field)] = value
    return to_text(base["header"], rows)


@pytest.mark.parametrize("edit, match", [
    (lambda b: _set(b, "fov_deg", "0"), r"row 1 .*field 'fov_deg' = '0' is not in \(0, 180\)"),  # was: no file/row
    (lambda b: _set(b, "lon_cam", "500"), r"row 1 .*field 'lon_cam' = '500' is not in \[-180, 180\]"),  # was: accepted
    (lambda b: _set(b, "alt_cam", "1e300"), r"field 'alt_cam' = '1e300' is not in"),  # was: accepted, NaN metrics
    (lambda b: _set(b, "pitch", "1000"), r"field 'pitch' = '1000' is not in \[0, 180\]"),  # was: accepted
    (lambda b: _set(b, "width", "1e300"), r"field 'width' = '1e300' is not a positive integer"),  # was: accepted
    (lambda b: _set(b, "image", "."), r"field 'image': path '\.' names the dataset root"),  # was: accepted
    (lambda b: _set(b, "image", "a\x00b.png"), r"field 'image': .*control characters"),  # was: bare ValueError
    (lambda b: _set(b, "x_TR_exact", ""), r"field 'x_TR_exact' = '' is empty while"),  # was: silent fallback
    (lambda b: _set(b, "weather", "x" * 200_000), r"line 2: malformed CSV"),  # was: csv.Error
    (lambda b: to_text(b["header"], [b["rows"][0] + ["extra"]]), r"row 1 .*45 field\(s\), the header has 44"),
    (lambda b: to_text(b["header"], [b["rows"][0][:-3]]), r"row 1 .*41 field\(s\), the header has 44"),
    (lambda b: to_text(b["header"] + ["alt_cam"], [r + ["1e4"] for r in b["rows"]]), r"alt_cam appear more than once"),
    (lambda b: to_text(b["header"], [*b["rows"], b["rows"][0]]), r"row 4 .*same image and runway VBLA 09 as row 1"),
    (lambda b: to_text(b["header"], b["rows"]).encode() + "x;\xe9\n".encode("latin-1"), r"not UTF-8"),
])
def test_found_csv_examples(base, edit, match):
    out, csv_path, _ = read(base, edit(base), target_runway_only=False)
    assert isinstance(out, ValueError) and str(csv_path) in str(out)
    assert re.search(match, str(out)), str(out)


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["VBLA"]["09"]["A"]["coordinate"].update(altitude=10**400), r"is not a finite number"),  # OverflowError
    (lambda d: d["VBLA"]["09"]["A"]["coordinate"].update(latitude=True), r"= True is not a number"),  # was: 1.0
    (lambda d: d["VBLA"]["09"]["A"]["coordinate"].update(longitude=1000), r"is not in \[-180, 180\]"),  # accepted
    (lambda d: d["VBLA"]["09"].update(C=d["VBLA"]["09"]["D"]), r"degenerate runway corners"),  # was: NaN metrics
    (lambda d: d.update(vbla=d["VBLA"]), r"airports 'VBLA' and 'vbla' are the same airport"),  # was: overwritten
])
def test_found_db_examples(base, edit, match):
    db = copy.deepcopy(base["db"])
    edit(db)
    out, _, db_path = read(base, db=db)
    assert isinstance(out, ValueError) and str(db_path) in str(out)
    assert re.search(match, str(out)), str(out)
