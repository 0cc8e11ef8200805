import math
import sqlite3

import numpy as np
import pytest

from vbl_robust.campaigns import ResultStore
from vbl_robust.campaigns.store import decode_points, encode_points


def row(key, **kw):
    r = {"key": key, "experiment": "t", "kind": "search", "role": "main", "method": "random", "sample_id": "s",
         "sample_index": 0, "status": "done", "worst_m": 1.0, "verdict": "no breach found", "nfev": 3}
    r.update(kw)
    return r


def test_wal_mode_and_unique_keys(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        assert st.commit([row("a"), row("b")]) == 2
        assert st.commit([row("a", worst_m=99.0), row("c")]) == 1  # a duplicate key is ignored, not doubled
        assert st.count() == 3
        assert {r["key"]: r["worst_m"] for r in st.jobs()}["a"] == 1.0
    con = sqlite3.connect(tmp_path / "r.sqlite")
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    with pytest.raises(sqlite3.IntegrityError):
        con.execute("INSERT INTO jobs (key, status) VALUES ('a', 'done')")


def test_points_round_trip_with_failed_values():
    xs = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    fs = np.array([0.5, np.nan, np.inf])
    x2, f2 = decode_points(encode_points(xs, fs))
    assert np.array_equal(x2, xs)
    assert f2[0] == 0.5 and math.isnan(f2[1]) and math.isnan(f2[2])


def test_campaign_binding_refuses_other_settings(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.bind_campaign("x", {"a": 1, "b": [1, 2]}, {"kind": "oracle", "sha256": None})
        st.bind_campaign("x", {"b": [1, 2], "a": 1}, {"kind": "oracle", "sha256": None})  # same: fine
        with pytest.raises(ValueError, match=r"other settings \(b\[1\]"):
            st.bind_campaign("x", {"a": 1, "b": [1, 3]}, {"kind": "oracle", "sha256": None})
        with pytest.raises(ValueError, match="detector"):
            st.bind_campaign("x", {"a": 1, "b": [1, 2]}, {"kind": "default", "sha256": "ff", "name": "m"})


def test_runs_record_provenance(tmp_path):
    with ResultStore(tmp_path / "r.sqlite") as st:
        rid = st.begin_run({"code_version": "1.0", "model_sha256": "ab", "config": {"n": 3}, "seed": 7,
                            "dataset": {"n": 3}, "jobs_total": 5, "jobs_skipped": 0})
        st.end_run(rid, "finished", 5, 1.5)
        (run,) = st.runs()
    assert run["code_version"] == "1.0" and run["config"] == {"n": 3} and run["seed"] == 7
    assert run["status"] == "finished" and run["jobs_done"] == 5 and run["finished_at"]


def test_open_existing_names_the_missing_store(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results store"):
        ResultStore.open_existing(tmp_path)
