"""Budgets read off one stamped run: Budget fields and keys, stored times, derived rows, the report's marking."""

from __future__ import annotations

import math
import sqlite3

import numpy as np
import pytest

import vbl_robust.search.base as base_module
from vbl_robust.analysis.readoff import main_rows, read_off, read_off_rows
from vbl_robust.analysis.summary import summarize
from vbl_robust.campaigns.work import search_row
from vbl_robust.constants import Verdict
from vbl_robust.search.anytime import at_budget
from vbl_robust.search.api import maximize
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import BoxSpec, CampaignSpec, Job, roll_box
from vbl_robust.specs.kinds import JobStatus
from vbl_robust.store import schema
from vbl_robust.store.core import ResultStore
from vbl_robust.store.rows import Points


def test_a_budget_without_reads_keeps_its_dict_and_label():
    b = Budget(max_seconds=0.5, stop_at_breach=False)
    assert b.to_dict() == {"max_evals": None, "max_seconds": 0.5, "max_iters": None, "stop_at_breach": False}
    assert b.label == "0.5 s, no early stop" and not b.reads and b.min_evals is None


def test_a_reading_budget_round_trips_and_lists_its_budgets():
    b = Budget(max_seconds=2.0, stop_at_breach=False, read_seconds=(1.0, 0.1, 2.0), read_evals=(50, 10))
    assert b.read_seconds == (0.1, 1.0, 2.0) and b.read_evals == (10, 50) and b.min_evals == 50
    assert Budget.from_dict(b.to_dict()) == b
    assert [x.label for x in b.read_budgets()] == ["0.1 s, no early stop", "1 s, no early stop",
                                                   "2 s, no early stop", "10 evals, no early stop",
                                                   "50 evals, no early stop"]
    assert "read at 0.1, 1, 2 s; 10, 50 evals" in b.label


@pytest.mark.parametrize("kw", [{"read_seconds": (3.0,)}, {"read_seconds": (0.0,)}, {"read_evals": (0,)},
                                {"max_seconds": None, "max_evals": 10, "read_evals": (5,)},
                                {"max_evals": 10, "read_evals": (20,)}])
def test_bad_read_budgets_are_refused(kw):
    with pytest.raises(ValueError, match="read_"):
        Budget(**{"max_seconds": 2.0, **kw})


def test_points_keep_their_times_and_an_old_blob_has_none():
    p = Points([[1.0], [2.0]], [3.0, 4.0], ("", "x"), [0.1, 0.25])
    back = Points.from_blob(p.to_blob())
    assert back == p and np.array_equal(back.times, [0.1, 0.25])
    assert Points.from_blob(Points([[1.0]], [3.0]).to_blob()).times is None
    with pytest.raises(ValueError, match="times"):
        Points([[1.0]], [3.0], (), [0.1, 0.2])


def test_a_schema_2_store_opens_as_the_current_schema(tmp_path):
    con = sqlite3.connect(tmp_path / "r.sqlite")
    con.executescript(schema.DDL)
    con.execute("PRAGMA user_version = 2")
    con.commit()
    con.close()
    with ResultStore(tmp_path / "r.sqlite") as st:
        assert st.count() == 0
    con = sqlite3.connect(tmp_path / "r.sqlite")
    assert con.execute("PRAGMA user_version").fetchone()[0] == schema.SCHEMA_VERSION


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t

    def wrap(self, f):
        def g(x):
            self.t += 0.003 + 0.01 * len(x)
            return f(x)
        return g


def f(x):
    return 800.0 + 400.0 * np.cos(x[:, 0] / 3.0)  # breaches (> 1000 m) near roll 0


def _stored_run(tmp_path, monkeypatch, method="random"):
    clock = Clock()
    monkeypatch.setattr(base_module, "_clock", clock)
    box = roll_box(10.0)
    budget = Budget(max_seconds=0.5, stop_at_breach=False, read_seconds=(0.05, 0.2, 0.5), read_evals=(5, 60))
    r = maximize(clock.wrap(f), box.box, method, max_seconds=0.5, min_evals=60, time_marks=budget.read_seconds)
    spec = CampaignSpec("t", ())
    job = Job("t", "s0", "fp", 0, "search", "main", method, box, budget, 0, {}, "ctx")
    row = search_row(job, r, spec.settings, None, 1.0)
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.commit([row])
        (stored,) = st.jobs(with_points=True)
    return r, stored, spec


def test_rows_read_off_a_stored_run_equal_the_search_read_at_each_budget(tmp_path, monkeypatch):
    r, stored, spec = _stored_run(tmp_path, monkeypatch)
    assert stored.points.times is not None and stored.nfev >= 60
    rows = read_off_rows([stored], spec.settings.eps_safe_m, spec.settings.penalty_m)
    assert [x.budget_label for x in rows] == [b.label for b in stored.budget.read_budgets()]
    for x, b in zip(rows, stored.budget.read_budgets(), strict=True):
        want = at_budget(r, seconds=b.max_seconds, evals=b.max_evals)
        assert x.read_from == stored.budget_label and x.key.startswith(stored.key)
        assert x.nfev == want.nfev and x.nit == want.nit and x.worst_m == pytest.approx(want.fun)
        assert x.verdict is (Verdict.BREACH if want.fun > 1000 else Verdict.NO_BREACH_FOUND)
        assert np.all(x.points.times <= (b.max_seconds or math.inf)) and len(x.points) == x.nfev
    assert rows[3].nfev == 5 and rows[4].nfev == 60
    s = summarize(rows, spec.settings.eps_safe_m)
    assert all(line.read_from == stored.budget_label for line in s)


def test_a_time_budget_before_the_first_evaluation_finds_nothing(tmp_path, monkeypatch):
    r, stored, spec = _stored_run(tmp_path, monkeypatch)
    early = read_off(stored, Budget(max_seconds=0.001, stop_at_breach=False), spec.settings.eps_safe_m, spec.settings.penalty_m)
    assert early.nfev == 0 and early.worst_m is None and early.verdict is Verdict.NO_BREACH_FOUND
    (line,) = summarize([early], spec.settings.eps_safe_m)
    assert line.survival == 100.0 and line.n_empty == 1 and math.isnan(line.median_worst_m)


def test_a_run_not_measured_reads_as_not_measured_at_every_budget(tmp_path, monkeypatch):
    _, stored, spec = _stored_run(tmp_path, monkeypatch)
    failed = stored.replace(status=JobStatus.NOT_MEASURED, points=None, worst_m=None, verdict=Verdict.NOT_MEASURED,
                            reason="tool error: boom")
    rows = read_off_rows([failed], spec.settings.eps_safe_m, spec.settings.penalty_m)
    assert len(rows) == 5 and all(x.status is JobStatus.NOT_MEASURED and x.read_from for x in rows)
    lines = summarize(rows, spec.settings.eps_safe_m)
    assert all(ln.n == 0 and ln.not_measured == 1 and math.isnan(ln.survival) for ln in lines)


def test_rows_without_reads_pass_through(tmp_path, monkeypatch):
    _, stored, spec = _stored_run(tmp_path, monkeypatch)
    plain = stored.replace(budget=Budget(max_evals=10), box=BoxSpec(stored.box.box, "b", 1.0))
    assert read_off_rows([plain], spec.settings.eps_safe_m, spec.settings.penalty_m) == [plain]


def test_export_and_main_rows_add_the_read_off_rows(tmp_path, monkeypatch):
    from vbl_robust.analysis.tables import flat_rows

    _, stored, _ = _stored_run(tmp_path, monkeypatch)
    spec = CampaignSpec("t", ())
    with ResultStore(tmp_path / "r.sqlite") as st:
        st.bind_campaign("t", spec.to_dict(), {"kind": "oracle", "sha256": None})
        lines, cols = flat_rows(st)
        assert "read_from" in cols and [ln["read_from"] for ln in lines] == [None] + [stored.budget_label] * 5
        assert lines[2]["max_seconds"] == 0.2 and lines[5]["max_evals"] == 60
        # a spec without reading budgets: stored rows as they are
        assert len(main_rows(st, spec)) == 1
