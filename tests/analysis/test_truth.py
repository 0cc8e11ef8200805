"""vbl-robust truth: a dense grid on the images every method left surviving tells whether "no breach found" was
true; the counts are recomputed here from both stores."""

import pytest
from typer.testing import CliRunner

from vbl_robust.analysis.breach import survived
from vbl_robust.analysis.readoff import main_rows
from vbl_robust.analysis.truth import survivors_of_every_method, true_survival
from vbl_robust.cli import app
from vbl_robust.store.core import ResultStore

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("truth") / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "6", "--roll", "30", "--contrast", "0.8,1.2",
                              "--methods", "random,georobust", "--max-evals", "2", "--oracle", "--oracle-noise", "0.3",
                              "--width", "320", "--height", "320", "--workers", "1", "--no-landscape", "--no-report",
                              "-q"])
    assert res.exit_code == 0, res.output
    return out


def test_the_grid_runs_on_the_images_every_method_left_surviving(run):
    res = runner.invoke(app, ["truth", str(run), "--counts", "13,3", "--workers", "1", "--no-report", "-q"])
    assert res.exit_code == 0, res.output
    with ResultStore.open_existing(run) as st:
        spec, box, methods, keep = survivors_of_every_method(st)
        rows = [r for r in main_rows(st, spec, with_trace=False) if r.box_label == box.label]
    eps = spec.settings.eps_safe_m
    assert keep == sorted({r.sample_id for r in rows} - {r.sample_id for r in rows if not survived(r, eps)},
                          key=lambda s: next(r.sample_index for r in rows if r.sample_id == s))
    truth = run.with_name(run.name + "-truth")
    with ResultStore.open_existing(truth) as t:
        grids = {r.sample_id: r for r in t.jobs(role="reference", with_trace=False)}
    assert set(grids) == set(keep) and keep  # the fixture leaves some survivors (else the test says nothing)
    hit = {sid for sid, g in grids.items() if not survived(g, eps)}
    ts = true_survival(run)
    assert (ts.survivors_any, ts.gridded, ts.grid_breaches) == (len(keep), len(keep), len(hit))
    assert ts.true_survivors == len(keep) - len(hit) and ts.images == 6 and ts.counts == (13, 3)
    for m in methods:  # every grid breach is a miss of every method; plus the other methods' breaches it missed
        others = {r.sample_id for r in rows if r.method != m and not survived(r, eps)}
        mine = {r.sample_id for r in rows if r.method == m and not survived(r, eps)}
        assert ts.missed[m] == len((others | hit) - mine)
    assert f"true survival {ts.true_survivors} of 6" in res.output
    # a rerun resumes: nothing new
    again = runner.invoke(app, ["truth", str(run), "--counts", "13,3", "--workers", "1", "--no-report", "-q"])
    assert again.exit_code == 0 and "0 new jobs" in again.output


def test_bad_counts_are_refused(run):
    for counts, msg in (("13", "need 2 counts"), ("13,x", "expected comma-separated integers"),
                        ("100000,100000", "exceeds the bound")):
        res = runner.invoke(app, ["truth", str(run), "--counts", counts, "--out", str(run.parent / "t2"), "-q"])
        assert res.exit_code == 2 and msg in res.output, res.output
