"""``paper.bundle.provenance``: the wall time of runs, including those killed before they recorded their end."""

import sqlite3
from pathlib import Path

import pytest

from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.paper.bundle import provenance
from vbl_robust.scenes.generate import generate
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.store.core import ResultStore


def test_a_killed_run_counts_up_to_its_last_stored_job_not_up_to_now(tmp_path):
    spec = CampaignSpec("wall-test", (Block(boxes=(roll_box(5),), methods=("random",),
                                            budgets=(Budget(max_evals=4),)),), seed=1)
    path = tmp_path / "results.sqlite"
    with ResultStore(path) as store:
        run_campaign(spec, list(generate(2, seed=0, width=96, height=96)), store, detector=DetectorSpec.oracle(1.0))
    # as a SIGKILL leaves it: the run never recorded its end; it began on 1 Dec, its last job ended 90 min later
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE runs SET status = 'running', finished_at = NULL, seconds = NULL, "
                    "started_at = '2026-12-01T10:00:00+00:00'")
        con.execute("UPDATE jobs SET finished_at = '2026-12-01T11:00:00+00:00'")
        con.execute("UPDATE jobs SET finished_at = '2026-12-01T11:30:00+00:00' WHERE rowid = (SELECT max(rowid) FROM jobs)")
    con.close()
    with ResultStore.open_existing(tmp_path) as store:
        assert provenance(store)["totals"]["wall_s"] == 5400.0
    # a run that recorded its end keeps its own seconds
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE runs SET status = 'finished', seconds = 12.5")
    con.close()
    with ResultStore.open_existing(tmp_path) as store:
        assert provenance(store)["totals"]["wall_s"] == 12.5


def test_a_check_tells_a_changed_finding_from_numeric_drift(tmp_path):
    """reproduce --check-against on another machine: the same verdicts with other evaluation counts or a slightly
    other worst error are drift (reported with its size, exit 0); another verdict or status is a finding."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from vbl_robust.paper.bundle import compare_runs

    base = {"key": ["a", "b", "c"], "budget_label": ["x", "x", "x"], "max_seconds": [None, None, None],
            "status": ["done"] * 3, "verdict": ["breach", "no breach found", "no breach found"],
            "nfev": [291, 40, 40], "nit": [5, 3, 3], "worst_roll_deg": [1.0, 2.0, 3.0], "worst_m": [954.039, 10.0, 20.0]}
    other = dict(base, nfev=[293, 40, 40], worst_m=[954.050, 10.0, 20.0])
    pq.write_table(pa.table(base), tmp_path / "a.parquet")
    pq.write_table(pa.table(other), tmp_path / "b.parquet")
    c = compare_runs(tmp_path / "a.parquet", tmp_path / "b.parquet")
    assert c["differ"] == [] and c["drift"] == ["a"] and abs(c["drift_m"] - 0.011) < 1e-9
    lost = dict(base, verdict=["breach", "breach", "no breach found"])
    pq.write_table(pa.table(lost), tmp_path / "c.parquet")
    c = compare_runs(tmp_path / "a.parquet", tmp_path / "c.parquet")
    assert c["differ"] == ["b"] and c["drift"] == []


def test_bundle_index_links_stay_relative_and_a_bundle_never_overwrites_its_runs(tmp_path):
    from vbl_robust.paper.bundle import write_bundle
    from vbl_robust.paper.claims_page import write_index
    from vbl_robust.store.pack import restore_store

    name = "javascript:alert(1)"
    (tmp_path / name).mkdir()
    (tmp_path / name / "report.html").write_text("x")
    page = write_index(tmp_path, [name]).read_text()
    assert 'href="javascript%3Aalert%281%29/report.html"' in page and 'href="javascript:' not in page
    with pytest.raises(ValueError, match="not into their directory"):
        write_bundle(tmp_path, tmp_path)
    packed = tmp_path / "cut.sqlite.xz"
    import lzma

    packed.write_bytes(lzma.compress(b"x" * 10000)[:40])  # a truncated pack
    with pytest.raises(ValueError, match=r"cut\.sqlite\.xz: not a complete packed store"):
        restore_store(packed, tmp_path / "restored")
    assert not (tmp_path / "restored" / "results.sqlite").exists()


def test_a_bundle_killed_midway_leaves_the_previous_bundle_whole(tmp_path, monkeypatch):
    """A bundle killed after its first experiment left experiments without index.html / claims.md; now it is
    written into a staging directory and published only when complete; a packed store is kept without --stores."""
    import vbl_robust.report.build as report
    from vbl_robust.paper.bundle import write_bundle
    from vbl_robust.store.core import PACKED

    spec = CampaignSpec("bundle-kill", (Block(boxes=(roll_box(5),), methods=("random",),
                                              budgets=(Budget(max_evals=4),)),), seed=1)
    root, out = tmp_path / "runs", tmp_path / "bundle"
    for name in ("exp-a", "exp-b"):
        with ResultStore(root / name / "results.sqlite") as store:
            run_campaign(spec, list(generate(1, seed=0, width=96, height=96)), store,
                         detector=DetectorSpec.oracle(1.0))
    write_bundle(root, out, stores=True)
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert {Path("index.html"), Path("claims.md"), Path("exp-a/report.html"), Path("exp-b") / PACKED} <= set(before)

    real, calls = report.build_report, []

    def killed_on_the_second(run, dest, *a, **k):
        calls.append(run)
        if len(calls) == 2:
            raise KeyboardInterrupt  # what SIGINT raises mid-bundle
        return real(run, dest, *a, **k)

    monkeypatch.setattr(report, "build_report", killed_on_the_second)
    with pytest.raises(KeyboardInterrupt):
        write_bundle(root, tmp_path / "first")  # a first bundle killed: nothing at all, not exp-a alone
    assert not (tmp_path / "first").exists()
    calls.clear()
    with pytest.raises(KeyboardInterrupt):
        write_bundle(root, out)
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle", "runs"]  # no staging directory left
    monkeypatch.setattr(report, "build_report", real)
    write_bundle(root, out)  # without --stores: the packed stores stay
    assert (out / "exp-b" / PACKED).read_bytes() == before[Path("exp-b") / PACKED]


def test_a_bundles_report_shows_its_figures_as_files_and_is_rebuilt_from_its_packed_store(tmp_path, monkeypatch):
    """A committed bundle's report.html links figures/*.png (no base64: pages of kB, figures git can share between
    versions); refresh_bundle(reports=True) rebuilds it from the packed store alone, the rest left as it was."""
    import re

    from vbl_robust.paper.bundle import refresh_bundle, write_bundle
    from vbl_robust.store.core import PACKED

    spec = CampaignSpec("bundle-files", (Block(boxes=(roll_box(5),), methods=("random",),
                                               budgets=(Budget(max_evals=4),)),), seed=1)
    root, out = tmp_path / "runs", tmp_path / "bundle"
    source = {"kind": "synthetic", "n": 1, "seed": 0, "width": 96, "height": 96}  # the gallery rebuilds its image
    with ResultStore(root / "exp" / "results.sqlite") as store:
        run_campaign(spec, list(generate(1, seed=0, width=96, height=96)), store, detector=DetectorSpec.oracle(1.0),
                     dataset_source=source)
    write_bundle(root, out, stores=True)
    exp = out / "exp"
    page = (exp / "report.html").read_text()
    shown = re.findall(r'<img alt="[^"]*" src="([^"]*)"', page)
    assert "figures/gallery_01.png" in shown and "data:image" not in page
    assert sorted(shown) == sorted(p.relative_to(exp).as_posix() for p in (exp / "figures").glob("*.png"))
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    # the report of an older code version: another page, a stale figure; its store and job table are the truth
    (exp / "report.html").write_text("old")
    (exp / "figures" / "gone.png").write_bytes(b"stale")
    (exp / "figures" / shown[0].split("/")[-1]).unlink()
    monkeypatch.chdir(tmp_path)  # the bundle as a checkout names it, relative
    refresh_bundle(Path("bundle"), reports=True)
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after.keys() == before.keys()
    assert after[Path("exp/report.html")] == before[Path("exp/report.html")]
    for name in (Path("exp") / PACKED, Path("exp/jobs.parquet"), Path("exp/provenance.json")):
        assert after[name] == before[name]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle", "runs"]
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []  # no staging left
