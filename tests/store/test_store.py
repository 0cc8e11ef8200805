import dataclasses
import math
import re
import sqlite3
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vbl_robust.constants import Verdict
from vbl_robust.search.result import TraceRow
from vbl_robust.space import ParameterBox
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import JOB_KINDS, ROLES, BoxSpec
from vbl_robust.specs.kinds import JobStatus, RunStatus
from vbl_robust.store import core, schema
from vbl_robust.store.core import ResultStore
from vbl_robust.store.rows import JobRow, Points, RunProvenance, SampleRecord, decode_points, encode_points


def row(key, **kw):
    base = {"key": key, "experiment": "t", "kind": "search", "role": "main", "method": "random", "sample_id": "s",
            "sample_index": 0, "status": "done", "worst_m": 1.0, "verdict": "no breach found", "nfev": 3}
    return JobRow(**{**base, **kw})


def test_wal_mode_and_unique_keys(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        assert st.commit([row("a"), row("b")]) == 2
        assert st.commit([row("a", worst_m=99.0), row("c")]) == 1  # a duplicate key is ignored, not doubled
        assert st.count() == 3
        assert {r.key: r.worst_m for r in st.jobs()}["a"] == 1.0
    con = sqlite3.connect(tmp_path / "r.sqlite")
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    with pytest.raises(sqlite3.IntegrityError):
        con.execute("INSERT INTO jobs (key, status) VALUES ('a', 'done')")



def test_jobs_read_the_measured_or_the_unmeasured_alone_old_failed_rows_included(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.commit([row("a"), row("b", status="not measured", reason="tool_error: boom", verdict="not measured"),
                   row("c", sample_index=1)])
        st._con.execute("UPDATE jobs SET status = 'failed' WHERE key = 'c'")  # a store from before the name
        assert [r.key for r in st.jobs(measured=False)] == ["b", "c"]
        assert all(not r.measured for r in st.jobs(measured=False))
        assert [r.key for r in st.jobs(measured=True)] == ["a"]
        assert [r.key for r in st.jobs()] == ["a", "b", "c"]

def test_points_round_trip_with_failed_values():
    xs = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    fs = np.array([0.5, np.nan, np.inf])
    x2, f2 = decode_points(encode_points(xs, fs))
    assert np.array_equal(x2, xs)
    assert f2[0] == 0.5 and math.isnan(f2[1]) and math.isnan(f2[2])
    p = Points.from_blob(encode_points(xs, fs, ("", "no_detection", "non_finite_value")))
    assert p.reasons == ("", "no_detection", "non_finite_value") and Points.from_blob(encode_points(xs, fs)).reasons == ("",) * 3


def test_rows_read_by_attribute(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.commit([row("a", box=BoxSpec(ParameterBox({"roll_deg": (-5, 5)}), "±5°", 5.0), budget=Budget(max_evals=3),
                       worst_x={"roll_deg": 1.5}, points=Points([[1.5], [0.0], [-2.0]], [1.0, 0.5, 5000.0],
                                                                ("", "", "no_detection")))])
        (r,) = st.jobs(with_points=True)
    assert r.status is JobStatus.DONE and r.verdict is Verdict.NO_BREACH_FOUND and r.box_label == "±5°"
    assert r.budget_label == "3 evals" and r.worst_x == {"roll_deg": 1.5} and r.nfev == 3
    assert r.points.reasons[2] == "no_detection"


def test_campaign_binding_refuses_other_settings_once_a_job_is_stored(tmp_path):
    oracle = {"kind": "oracle", "sha256": None}
    model = {"kind": "default", "sha256": "ff", "name": "m"}
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.bind_campaign("x", {"a": 1, "b": [1, 2]}, oracle)
        st.add_samples([SampleRecord("s1", 0)])
        # nothing computed yet (e.g. the run failed on its model): the store is bound anew, its samples forgotten
        st.bind_campaign("x", {"a": 1, "b": [1, 3]}, model)
        assert st.campaign().stored_spec == {"a": 1, "b": [1, 3]} and st.campaign().detector == model
        assert st.samples() == {}
        st.commit([row("a")])
        st.bind_campaign("x", {"b": [1, 3], "a": 1}, model)  # same: fine
        st.bind_campaign("x", {"b": [1, 3], "a": 1, "figures": ["pnp"]}, model)  # presentation only: recorded
        assert st.campaign().stored_spec["figures"] == ["pnp"]
        with pytest.raises(ValueError, match=r"other settings \(b\[1\]"):
            st.bind_campaign("x", {"a": 1, "b": [1, 2]}, model)
        with pytest.raises(ValueError, match="holds results of detector 'm'"):
            st.bind_campaign("x", {"a": 1, "b": [1, 3]}, oracle)


def test_the_stored_campaign_is_a_record_with_its_spec_and_one_error_when_there_is_none(tmp_path):
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box

    spec = CampaignSpec("t", (Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=3),)),),
                        seed=4)
    detector = {"kind": "oracle", "sha256": None}
    with ResultStore(tmp_path / "r.sqlite") as st:
        assert st.campaign() is None and not st.holds_campaign()
        for read in (st.spec, st.require_campaign):  # the one error of a store nothing was run into
            with pytest.raises(ValueError, match=r"r\.sqlite: the results store holds no campaign yet"):
                read()
        st.bind_campaign(spec.name, spec.to_dict(), detector)
        camp = st.require_campaign()
        assert st.holds_campaign() and st.spec() == spec == camp.spec and camp.name == "t"
        assert camp.detector == detector and camp.stored_spec == spec.to_dict()
        assert camp.to_dict() == {"name": "t", "spec": spec.to_dict(), "detector": detector,
                                  "created_at": camp.created_at}
        with pytest.raises(dataclasses.FrozenInstanceError):
            camp.name = "other"  # type: ignore[misc]


def test_samples_are_records_read_back_as_written(tmp_path):
    a = SampleRecord("a", 1, 2500.5, "q1", 96, 64, "f" * 8, '{"image": "a.png"}')
    b = SampleRecord("b", 0)
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.add_samples([a, b])
        st.add_samples([SampleRecord("a", 7)])  # a sample already stored is kept
        got = st.samples()
    assert list(got) == ["b", "a"] and got == {"a": a, "b": b}  # by sample index
    assert a.meta == {"image": "a.png"} and b.meta == {} and a.columns()["meta_json"] == a.meta_json
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.width = 1  # type: ignore[misc]


def test_runs_record_provenance(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        rid = st.begin_run(RunProvenance(code_version="1.0", model_sha256="ab", config={"n": 3}, seed=7,
                                         dataset={"n": 3}, jobs_total=5, jobs_skipped=0))
        (running,) = st.runs()
        st.end_run(rid, RunStatus.FINISHED, 5, 1.5)
        (run,) = st.runs()
    assert running.status is RunStatus.RUNNING and running.jobs_done == 0 and running.finished_at is None
    p = run.provenance
    assert p.code_version == "1.0" and p.config == {"n": 3} and p.seed == 7 and p.dataset == {"n": 3}
    assert run.status is RunStatus.FINISHED and run.jobs_done == 5 and run.finished_at and run.seconds == 1.5
    assert run.run_id == rid and run.started_at == running.started_at


def test_open_existing_names_the_missing_store(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results store"):
        ResultStore.open_existing(tmp_path)


def old_store(path, *added, version=0):
    """A store of an older layout at ``path``: today's schema without the columns of the schema versions ``added``
    (their comments say "(schema N)"), one job row (worst 12.5 m, 4 evaluations), ``user_version`` = ``version``."""
    lines = [ln for ln in schema.DDL.splitlines() if not any(f"(schema {v})" in ln for v in added)]
    con = sqlite3.connect(path)
    con.executescript(re.sub(r",(\s*(--[^\n]*)?\n\))", r"\1", "\n".join(lines)))  # no comma after the last column
    con.execute("INSERT INTO jobs (key, experiment, kind, role, method, sample_id, sample_index, status, worst_m, "
                "verdict, nfev, options_json) VALUES ('k', 'audit', 'search', 'main', 'random', 's', 0, 'done', 12.5, "
                "'no breach found', 4, '{}')")
    con.execute(f"PRAGMA user_version = {version}")
    con.commit()
    columns = {r[1] for r in con.execute("PRAGMA table_info(jobs)")}
    con.close()
    return columns


def test_a_store_of_schema_1_opens_and_is_migrated(tmp_path):
    assert not {"n_failed", "worst_corners_json"} & old_store(tmp_path / "r.sqlite", 2, 4)
    with ResultStore(tmp_path / "r.sqlite") as st:
        (r,) = st.jobs()
        assert (r.worst_m, r.nfev, r.n_failed, r.failures, r.worst_reason) == (12.5, 4, None, {}, None)
        st.commit([row("new", n_failed=2, failures={"no_detection": 2}, worst_reason="")])
        assert st.jobs()[1].failures == {"no_detection": 2}
    con = sqlite3.connect(tmp_path / "r.sqlite")
    assert con.execute("PRAGMA user_version").fetchone()[0] == schema.SCHEMA_VERSION
    con.execute("PRAGMA user_version = 99")
    con.commit()
    con.close()
    with pytest.raises(ValueError, match="schema version 99 is newer than this vbl-robust's"):
        ResultStore(tmp_path / "r.sqlite")


# -- property: any valid JobRow survives commit -> jobs() unchanged --------------------------------------------
finite = st.floats(allow_nan=False, allow_infinity=False)
text = st.text(max_size=12)
json_value = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), finite, text)
json_dict = st.dictionaries(text, st.one_of(json_value, st.lists(json_value, max_size=3)), max_size=3)


@st.composite
def boxes(draw):
    names = draw(st.lists(st.sampled_from(["roll_deg", "contrast", "gamma"]), min_size=1, max_size=3, unique=True))
    lows = draw(st.lists(st.floats(-1e6, 1e6), min_size=len(names), max_size=len(names)))
    widths = draw(st.lists(st.floats(1e-3, 1e6), min_size=len(names), max_size=len(names)))
    box = ParameterBox({n: (lo, lo + w) for n, lo, w in zip(names, lows, widths, strict=True)})
    return BoxSpec(box, draw(text), draw(finite))


budgets = st.one_of(  # at least one budget is set
    st.builds(Budget, max_evals=st.integers(1, 10**6), max_seconds=st.none() | st.floats(1e-3, 1e4),
              max_iters=st.none() | st.integers(1, 10**4), stop_at_breach=st.booleans()),
    st.builds(Budget, max_seconds=st.floats(1e-3, 1e4), stop_at_breach=st.booleans()),
)

trace_rows = st.builds(
    TraceRow, iteration=st.integers(1, 1000), nfev=st.integers(0, 10**6), elapsed=finite, best_value=finite,
    best_x=st.none() | st.lists(finite, min_size=1, max_size=3).map(tuple), batch_size=st.integers(0, 1000),
    n_failed=st.integers(0, 1000), po_count_before=st.none() | st.integers(0, 100),
    remaining_area=st.none() | finite, upper_bound=st.none() | finite,
    extra=st.dictionaries(text, st.one_of(st.integers(-100, 100), finite, text), max_size=2))


@st.composite
def points(draw):
    n, d = draw(st.integers(0, 6)), draw(st.integers(1, 3))
    xs = draw(st.lists(st.lists(finite, min_size=d, max_size=d), min_size=n, max_size=n))
    fs = draw(st.lists(finite | st.just(math.nan), min_size=n, max_size=n))
    reasons = draw(st.lists(st.sampled_from(["", "no_detection", "pnp_failed"]) | text, min_size=n, max_size=n))
    return Points(np.asarray(xs, dtype=np.float64).reshape(n, d), fs, tuple(reasons))


def opt(s):
    return st.none() | s


job_rows = st.builds(
    JobRow, key=st.text(min_size=1, max_size=16), experiment=text, kind=st.sampled_from(JOB_KINDS),
    role=st.sampled_from(ROLES), method=text, sample_id=text, sample_index=st.integers(0, 10**6),
    status=st.sampled_from(JobStatus), run_id=opt(st.integers(1, 10**6)), box=opt(boxes()), budget=opt(budgets),
    seed=opt(st.integers(0, 2**31 - 1)), options=json_dict, chain=opt(text), reason=opt(text), worst_m=opt(finite),
    worst_x=opt(st.dictionaries(st.sampled_from(["roll_deg", "contrast"]), finite, min_size=1)),
    verdict=opt(st.sampled_from(Verdict)), nfev=st.integers(0, 10**9), nit=st.integers(0, 10**6),
    n_failed=opt(st.integers(0, 10**6)), failures=st.dictionaries(st.text(min_size=1, max_size=12), st.integers(1, 10**6),
                                                                  max_size=3),
    worst_reason=opt(text), worst_corners=opt(st.lists(st.tuples(finite, finite), min_size=4, max_size=4).map(tuple)),
    search_status=opt(text), message=opt(text), search_s=opt(finite), job_s=opt(finite),
    upper_bound=opt(finite), bound_estimate=opt(finite), lipschitz_estimate=opt(finite),
    trace=st.lists(trace_rows, max_size=3).map(tuple), points=opt(points()), payload=opt(json_dict),
    finished_at=opt(text),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(job_rows, max_size=4, unique_by=lambda r: r.key))
def test_job_rows_round_trip_through_the_store(rows):
    with tempfile.TemporaryDirectory() as d, ResultStore(Path(d) / "r.sqlite") as store:
        assert store.commit(rows) == len(rows)
        back = store.jobs(with_points=True, with_trace=True)
    assert back == sorted(rows, key=lambda r: r.sample_index)


def test_worst_corners_are_stored_and_a_schema_3_store_reads_them_as_none(tmp_path):
    corners = ((310.5, 454.25), (303.5, 454.75), (298.5, 470.5), (309.75, 470.25))
    with ResultStore(tmp_path / "new.sqlite") as st:
        st.commit([row("a", worst_corners=corners), row("b")])
        assert [r.worst_corners for r in st.jobs()] == [corners, None]
    columns = old_store(tmp_path / "old.sqlite", 4, version=3)
    assert "n_failed" in columns and "worst_corners_json" not in columns
    with ResultStore.open_existing(tmp_path / "old.sqlite") as st:  # read-only: migrated in memory
        assert [(r.worst_m, r.worst_corners) for r in st.jobs()] == [(12.5, None)]
    with ResultStore(tmp_path / "old.sqlite") as st:  # a writer adds the column on open
        st.commit([row("new", worst_corners=corners)])
        assert [r.worst_corners for r in st.jobs()] == [None, corners]
    con = sqlite3.connect(tmp_path / "old.sqlite")
    assert con.execute("PRAGMA user_version").fetchone()[0] == schema.SCHEMA_VERSION == 5


def test_run_status_strings_are_the_stored_values_and_a_run_reads_back_flat(tmp_path):
    assert [s.value for s in RunStatus] == ["running", "finished", "incomplete", "interrupted", "killed", "unknown"]
    with ResultStore(tmp_path / "r.sqlite") as st:
        rid = st.begin_run(RunProvenance(detector={"name": "d", "kind": "oracle"}, host="h", jobs_total=2))
        st.end_run(rid, "incomplete", 1, 2.0)  # the stored string is accepted as well as the enum
        (run,) = st.runs()
    con = sqlite3.connect(tmp_path / "r.sqlite")
    stored = con.execute("SELECT status, detector_json, jobs_done FROM runs").fetchone()
    con.close()
    assert stored == ("incomplete", '{"kind": "oracle", "name": "d"}', 1) and run.status is RunStatus.INCOMPLETE
    d = run.to_dict()  # a bundle's provenance.json: the columns, JSON ones under their names without "_json"
    assert set(d) == {c.removesuffix("_json") for c in schema.RUNS.names}
    assert d["status"] == "incomplete" and type(d["status"]) is str and d["detector"] == {"name": "d", "kind": "oracle"}
    assert d["host"] == "h" and d["jobs_total"] == 2 and d["run_id"] == rid and d["seconds"] == 2.0
    with pytest.raises(ValueError):
        RunStatus("done")


def test_the_schema_declares_each_table_once_and_its_ddl_is_what_stores_hold(tmp_path):
    """The DDL is generated from the column tables; the text SQLite keeps for each table is the one earlier versions
    wrote (a store's bytes do not depend on which version created it)."""
    assert [t.name for t in schema.TABLES] == ["campaign", "runs", "samples", "contents", "jobs", "digests"]
    ResultStore(tmp_path / "r.sqlite").close()
    con = sqlite3.connect(tmp_path / "r.sqlite")
    for t in schema.TABLES:
        assert [r[1] for r in con.execute(f"PRAGMA table_info({t.name})")] == list(t.names)
    contents = con.execute("SELECT sql FROM sqlite_master WHERE name = 'contents'").fetchone()[0]
    con.close()
    assert contents == ("CREATE TABLE contents (\n"
                        "    sample_id TEXT PRIMARY KEY,     -- a sample read from an image file: what its pixels were\n"
                        "    path TEXT, size INTEGER, mtime_ns INTEGER,\n"
                        "    sha256 TEXT                     -- of the file's bytes; recomputed only when size or mtime "
                        "changed\n)")


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(job_rows, max_size=4, unique_by=lambda r: r.key))
def test_points_on_demand_read_the_same_rows(rows):
    """What the report reads with (points left in the store until read) gives the rows the store was given."""
    with tempfile.TemporaryDirectory() as d:
        with ResultStore(Path(d) / "results.sqlite") as store:
            store.commit(rows)
        with ResultStore.open_existing(d, points_on_demand=True) as store:
            back = store.jobs(with_points=True, with_trace=True)
            assert back == sorted(rows, key=lambda r: r.sample_index)
            assert [r.points is None for r in back] == [r.points is None for r in sorted(rows, key=lambda r: r.sample_index)]


def test_points_on_demand_hold_a_bounded_cache_and_the_stored_bytes(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    made = [row(f"k{i}", sample_index=i, points=Points(rng.uniform(-5, 5, (1000, 2)), rng.uniform(0, 5000, 1000)))
            for i in range(40)]
    with ResultStore(tmp_path / "results.sqlite") as store:
        store.commit(made)
    one = made[0].points.xs.nbytes + made[0].points.fs.nbytes
    monkeypatch.setattr(core, "POINTS_CACHE_BYTES", 5 * one)
    with ResultStore.open_existing(tmp_path, points_on_demand=True) as store:
        rows = store.jobs(with_points=True)
        assert all(type(r.points).__name__ == "StoredPoints" and r.trace == () for r in rows)
        for r, m in zip(rows, made, strict=True):
            assert np.array_equal(r.points.xs, m.points.xs) and np.array_equal(r.points.fs, m.points.fs)
            assert r.points.to_blob() == m.points.to_blob()  # the stored bytes themselves
            assert len(store._cache) <= 5  # the rows read last, not every row read
        blob = store._con.execute("SELECT points FROM jobs WHERE key = 'k3'").fetchone()[0]
        assert rows[3].points.to_blob() == blob
    with pytest.raises(sqlite3.ProgrammingError):  # read while the store is open, never from a closed one
        rows[0].points.xs  # noqa: B018
    with ResultStore.open_existing(tmp_path) as store:  # the default still decodes every row's points at once
        assert all(type(r.points) is Points for r in store.jobs(with_points=True))
