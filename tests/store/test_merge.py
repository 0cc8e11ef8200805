"""``merge_runs`` / ``merge_store`` / ``vbl-robust merge``: parts of one campaign computed elsewhere joined into one run."""

import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.cli import app
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.paper.bundle import compare_runs
from vbl_robust.scenes.generate import generate
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.specs.kinds import RunStatus
from vbl_robust.store.core import ResultStore
from vbl_robust.store.lock import WriterLock
from vbl_robust.store.merge import MergedSource, MergeReport, merge_runs, merge_store
from vbl_robust.store.pack import pack_store

DET = DetectorSpec.oracle(1.0)


def _spec(seed=3):
    return CampaignSpec("merge-test", (Block(boxes=(roll_box(5), roll_box(10)), methods=("georobust", "random"),
                                             budgets=(Budget(max_evals=8),)),), seed=seed)


def _run(out, samples, spec=None):
    with ResultStore(out / "results.sqlite") as store:
        return run_campaign(spec or _spec(), samples, store, detector=DET)


def test_two_parts_merge_into_the_whole_run(tmp_path):
    samples = list(generate(3, seed=0, width=96, height=96))
    _run(tmp_path / "whole", samples)
    _run(tmp_path / "part1", samples[:2])        # one machine: the first two images
    _run(tmp_path / "part2", samples)            # another: all three, resuming nothing
    with ResultStore.open_existing(tmp_path / "part1") as st:  # as a GPU machine sends it back: packed
        packed = pack_store(st, tmp_path / "part1.sqlite.xz")
    res = CliRunner().invoke(app, ["merge", str(packed), str(tmp_path / "part2"), "--into", str(tmp_path / "joined")])
    assert res.exit_code == 0, res.output
    assert "part1.sqlite.xz: 8 job rows merged, 0 already" in res.output and "part2: 4 job rows merged, 8 already" in res.output
    check = compare_runs(tmp_path / "joined", tmp_path / "whole")
    assert check["rows"] == check["common"] == 12 and check["differ"] == []
    with ResultStore.open_existing(tmp_path / "joined") as st:
        runs = st.runs()
        rows = st.jobs()
        assert len(st.samples()) == 3
    assert [r.provenance.config["merged_from"] for r in runs] == [str(packed), str(tmp_path / "part2")]
    assert {r.run_id for r in rows} == {runs[0].run_id, runs[1].run_id}
    assert _run(tmp_path / "joined", samples).done == 0  # the joined run resumes: nothing left to do


def test_merge_refuses_another_campaign_a_held_store_and_an_empty_source(tmp_path):
    samples = list(generate(2, seed=0, width=96, height=96))
    _run(tmp_path / "a", samples)
    _run(tmp_path / "b", samples, _spec(seed=4))
    with ResultStore(tmp_path / "a" / "results.sqlite") as a, ResultStore.open_existing(tmp_path / "b") as b:
        before = a.count()
        with pytest.raises(ValueError, match="other settings"):
            merge_store(a, b)
        assert a.count() == before
    runner = CliRunner()
    res = runner.invoke(app, ["merge", str(tmp_path / "a"), str(tmp_path / "b"), "--into", str(tmp_path / "new")])
    assert res.exit_code == 2 and "belongs to another campaign or detector" in res.output, res.output
    assert not (tmp_path / "new").exists()  # every source is checked before anything is created
    _run(tmp_path / "c", samples)  # the same campaign as a: mergeable, but a run is writing a
    with WriterLock(tmp_path / "a" / "results.sqlite"):
        res = runner.invoke(app, ["merge", str(tmp_path / "c"), "--into", str(tmp_path / "a")])
    assert res.exit_code == 2 and "in use by PID" in res.output
    ResultStore(tmp_path / "e" / "results.sqlite").close()
    res = runner.invoke(app, ["merge", str(tmp_path / "e"), "--into", str(tmp_path / "a")])
    assert res.exit_code == 2 and "holds no job rows to merge" in res.output
    (tmp_path / "bad.sqlite.xz").write_bytes(b"not xz")
    res = runner.invoke(app, ["merge", str(tmp_path / "bad.sqlite.xz"), "--into", str(tmp_path / "a")])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output


def test_a_merge_refuses_other_pixels_under_the_same_names(tmp_path):
    """Issue 48 item 6: two runs whose jobs read other bytes for the same image file are not parts of one run."""
    import dataclasses
    import sqlite3

    from PIL import Image

    base = list(generate(1, seed=0, width=96, height=96))[0]
    path = tmp_path / "img.png"
    Image.fromarray(base.image).save(path)
    on_file = dataclasses.replace(base, image_path=path, _image=None, _loader=None)
    _run(tmp_path / "a", [on_file])
    _run(tmp_path / "b", [on_file])
    con = sqlite3.connect(tmp_path / "b" / "results.sqlite")  # as if b's machine had read other pixels
    con.execute("UPDATE contents SET sha256 = 'f00d'")
    con.commit()
    con.close()
    with ResultStore(tmp_path / "a" / "results.sqlite") as a, ResultStore.open_existing(tmp_path / "b") as b:
        assert a.differing_pixels(b) == [base.id]
        with pytest.raises(ValueError, match="image files of samples .* differ"):
            merge_store(a, b)


def test_merge_runs_returns_a_typed_report_and_unpacks_packed_stores_beside(tmp_path):
    samples = list(generate(2, seed=0, width=96, height=96))
    _run(tmp_path / "part1", samples[:1])  # 1 image x 2 boxes x 2 methods
    _run(tmp_path / "part2", samples)      # both images
    with ResultStore.open_existing(tmp_path / "part1") as st:
        packed = pack_store(st, tmp_path / "part1.sqlite.xz")
    part2 = tmp_path / "part2" / "results.sqlite"
    seen = []
    report = merge_runs([packed, part2], tmp_path / "joined", progress=seen.append)
    into = tmp_path / "joined" / "results.sqlite"
    assert report == MergeReport(into, (MergedSource(str(packed), 4, 0), MergedSource(str(part2), 4, 4)))
    assert (report.copied, report.already) == (8, 4) and [len(r.sources) for r in seen] == [1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["joined", "part1", "part1.sqlite.xz", "part2"]
    again = merge_runs([packed], into)  # a .sqlite file as the target; everything already there
    assert again == MergeReport(into, (MergedSource(str(packed), 0, 4),))
    with ResultStore.open_existing(into) as st:
        assert st.count() == 8 and [r.provenance.config["merged_from"] for r in st.runs()] == [str(packed), str(part2)]
    with pytest.raises(FileNotFoundError, match="no such packed store"):
        merge_runs([tmp_path / "gone.sqlite.xz"], into)
    (tmp_path / "bad.sqlite.xz").write_bytes(b"not xz")
    with pytest.raises(ValueError, match="not a complete packed store"):
        merge_runs([tmp_path / "bad.sqlite.xz"], into)


def test_a_merged_run_without_its_run_row_is_recorded_as_unknown(tmp_path):
    import shutil
    import sqlite3

    samples = list(generate(1, seed=0, width=96, height=96))
    _run(tmp_path / "a", samples)
    (tmp_path / "b").mkdir()
    shutil.copy(tmp_path / "a" / "results.sqlite", tmp_path / "b" / "results.sqlite")
    con = sqlite3.connect(tmp_path / "b" / "results.sqlite")
    con.execute("DELETE FROM runs")  # the jobs stay, pointing to a run the store no longer holds
    con.commit()
    con.close()
    with ResultStore(tmp_path / "c" / "results.sqlite") as c, ResultStore.open_existing(tmp_path / "b") as b:
        assert merge_store(c, b) == MergedSource(str(b.path), 4, 0)
        (run,) = c.runs()
        rows = c.jobs()
    assert run.status is RunStatus.UNKNOWN and run.provenance.config == {"merged_from": str(b.path)}
    assert run.jobs_done is None and run.provenance.code_version is None
    assert {r.run_id for r in rows} == {run.run_id}
