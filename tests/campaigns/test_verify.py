"""Rows checked against their own evaluations and their digests (issue 59): ``vbl-robust verify`` flags every
single-field edit of a committed row, and the reading commands leave the edited row out and say so."""

from __future__ import annotations

import json
import shutil
import sqlite3
import zlib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.analysis.readoff import main_rows
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.campaigns.verify import banner_lines, check_store, screen
from vbl_robust.cli import app
from vbl_robust.constants import Verdict
from vbl_robust.scenes.generate import generate
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.specs.kinds import JobStatus
from vbl_robust.store.core import ResultStore
from vbl_robust.store.digest import FindingKind, reseal
from vbl_robust.store.merge import merge_runs
from vbl_robust.store.rows import JobRow
from vbl_robust.store.schema import JOB_COLUMNS

runner = CliRunner()
SPEC = CampaignSpec("verify-test", (
    Block(boxes=(roll_box(5), roll_box(10)), methods=("random", "georobust"),
          budgets=(Budget(max_evals=6, stop_at_breach=False),)),
    Block(boxes=(roll_box(5), roll_box(10)), methods=("random",), budgets=(Budget(max_evals=3),), chain=True),
    Block(kind="pnp"),
), seed=2)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A tiny committed campaign: main searches, a chain with implied rows, PnP rows (the oracle detector)."""
    from vbl_robust.detect.shipped import DetectorSpec

    out = tmp_path_factory.mktemp("verify") / "run"
    with ResultStore(out / "results.sqlite") as store:
        run_campaign(SPEC, generate(2, seed=3, width=96, height=96), store,
                     detector=DetectorSpec("oracle", options={"noise_px": 0.5, "fail_outside": True}))
    return out


def _copy(src: Path, dst: Path) -> Path:
    dst.mkdir(parents=True)
    for f in src.iterdir():
        if f.name.startswith("results.sqlite"):
            shutil.copy2(f, dst / f.name)
    return dst


def _sql(run: Path, sql: str, args: tuple = ()) -> None:
    con = sqlite3.connect(run / "results.sqlite")
    with con:
        con.execute(sql, args)
    con.close()


def _raw(run: Path, where: str) -> dict:
    con = sqlite3.connect(run / "results.sqlite")
    cur = con.execute(f"SELECT {', '.join(JOB_COLUMNS)} FROM jobs WHERE {where} ORDER BY rowid LIMIT 1")
    row = dict(zip(JOB_COLUMNS, cur.fetchone(), strict=True))
    con.close()
    return row


def _verify(run: Path, *args: str):
    return runner.invoke(app, ["verify", str(run), *args])


# -- plausible single-field edits, one per stored column -----------------------------------------------------------
def _points(v: bytes | None) -> bytes:
    """The points blob with one value that is not the worst halved (the summary still holds); a blob where none."""
    if v is None:
        return zlib.compress(json.dumps({"xs": [[1.0]], "fs": [12042.0], "d": 1}).encode())
    d = json.loads(zlib.decompress(v))
    fs = d["fs"]
    j = min(range(len(fs)), key=lambda i: fs[i] if fs[i] is not None else float("inf"))
    fs[j] = (fs[j] or 1.0) * 0.5 if len(fs) > 1 else (fs[j] or 1.0) * 2
    return zlib.compress(json.dumps(d).encode())


def _trace(v: str | None) -> str:
    rows = json.loads(v) if v else []
    if not rows:
        return json.dumps([{"iteration": 1, "nfev": 1, "elapsed": 0.0, "best_value": 1.0, "best_x": None,
                            "batch_size": 1, "n_failed": 0}])
    rows[0]["best_value"] = 1.0
    return json.dumps(rows)


def _box(v: str | None) -> str:
    """The box widened to ±90° (a valid box: the row still reads)."""
    d = json.loads(v) if v else {"box": {"bounds": {"roll_deg": [-5.0, 5.0]}, "units": {"roll_deg": "deg"}},
                                 "label": "±5°", "level": 5.0}
    d["box"]["bounds"] = {k: [-90.0, 90.0] for k in d["box"]["bounds"]}
    return json.dumps(d)


def _budget(v: str | None) -> str:
    d = json.loads(v) if v else {}
    return json.dumps({**d, "max_evals": 1000})


def _payload(v: str | None) -> str:
    d = json.loads(v) if v else {}
    if "worst" in d:
        d["worst"]["error_m"] = 1.0
    else:
        d["edited"] = True
    return json.dumps(d)


def _corners(v: str | None) -> str:
    c = json.loads(v) if v else [[0.0, 0.0]] * 4
    return json.dumps([[u + 1.0, w] for u, w in c])


#: column -> the edit (old stored value -> new one): what a hand editing the store would plausibly do.
EDITS = {
    "key": lambda v: v[:-4] + "beef",
    "run_id": lambda v: (v or 0) + 1,
    "experiment": lambda v: f"{v}-x",
    "kind": lambda v: "risk" if v == "search" else "search",
    "role": lambda v: "reference" if v == "main" else "main",
    "method": lambda v: "grid" if v != "grid" else "random",
    "sample_id": lambda v: "synth_elsewhere",
    "sample_index": lambda v: (v or 0) + 7,
    "box_label": lambda v: "±90°",
    "box_level": lambda v: 90.0,
    "box_json": _box,
    "budget_label": lambda v: "1000 evals",
    "budget_json": _budget,
    "seed": lambda v: (v or 0) + 1,
    "options_json": lambda v: json.dumps({"lipschitz": 1.0}),
    "chain": lambda v: "c0ffee",
    "status": lambda v: "not measured" if v != "not measured" else "done",
    "reason": lambda v: "edited by hand",
    "worst_m": lambda v: 1.0,  # 12 042 m → 1 m: the survival of 33 %
    "worst_x_json": lambda v: json.dumps({"roll_deg": 90.0}),  # θ* of 90° in a ±5° box
    "verdict": lambda v: "no breach found" if v == "breach" else "breach",
    "nfev": lambda v: -5,
    "nit": lambda v: (v or 0) + 3,
    "search_status": lambda v: "converged" if v != "converged" else "budget_exhausted",
    "message": lambda v: f"{v} (edited)",
    "search_s": lambda v: (v or 0.0) * 2 + 1,
    "job_s": lambda v: (v or 0.0) * 2 + 1,
    "upper_bound": lambda v: 1.0,  # a forged certificate
    "bound_estimate": lambda v: 1.0,
    "lipschitz_estimate": lambda v: 1.0,
    "trace_json": _trace,
    "points": _points,
    "payload_json": _payload,
    "finished_at": lambda v: "2020-01-01T00:00:00+00:00",
    "n_failed": lambda v: (v or 0) + 1,
    "failures_json": lambda v: json.dumps({"no_detection": 3}),
    "worst_reason": lambda v: "no_detection" if v != "no_detection" else "",
    "worst_corners_json": _corners,
}

#: The rows edited: a searched main breach (its evaluations stored), an implied breach of a chain, a PnP row.
TARGETS = {
    "search": "kind = 'search' AND role = 'main' AND status = 'done' AND chain IS NULL AND verdict = 'breach' "
              "AND nfev > 1",
    "implied": "status = 'implied'",
    "pnp": "kind = 'pnp'",
}


def test_every_stored_column_has_an_edit():
    assert set(EDITS) == set(JOB_COLUMNS)  # a column added to the jobs table needs its edit here


@pytest.mark.parametrize("target", sorted(TARGETS))
def test_verify_flags_every_single_field_edit_and_the_report_leaves_the_row_out(pristine, tmp_path, target):
    """Each stored column of a committed row edited in turn (raw SQL): verify exits 1 naming the row; the reading
    commands (main_rows, store.jobs) leave it out and the first screen's banner says so."""
    row = _raw(pristine, TARGETS[target])
    outcome = {}
    for column, edit in EDITS.items():
        run = _copy(pristine, tmp_path / column)
        new = edit(row[column])
        assert new != row[column], column
        _sql(run, f"UPDATE jobs SET {column} = ? WHERE key = ?", (new, row["key"]))
        key = new if column == "key" else row["key"]
        res = _verify(run)
        assert res.exit_code == 1 and key in res.output, (column, res.output)
        with ResultStore.open_existing(run) as store:
            check = screen(store)
            assert key in check.inconsistent, (column, check.findings)
            assert key not in {r.key for r in store.jobs()}, column
            assert key not in {r.key for r in main_rows(store, SPEC, measured_only=False)}, column
            lines = banner_lines(check)
            assert lines[0].startswith("1 of ") and "inconsistent — not used" in lines[0], (column, lines)
        outcome[column] = sorted({f.kind.value for f in check.findings if f.key == key})
        shutil.rmtree(run)
    print(f"\n{target}: {len(outcome)} columns edited, {sum(map(bool, outcome.values()))} flagged")
    for column, kinds in outcome.items():
        print(f"  {column:20s} {', '.join(kinds)}")
    assert all(outcome.values())


def test_an_unedited_store_verifies_clean_and_its_head_is_the_reported_one(pristine, tmp_path):
    res = _verify(pristine)
    assert res.exit_code == 0, res.output
    assert res.output.count("\n") == 1 and "job rows consistent with their own evaluations" in res.output
    with ResultStore.open_existing(pristine) as store:
        check = check_store(store)
        n = store.count()
    assert check.ok and check.rows == check.covered == n and check.head is not None and len(check.heads) == 1
    assert f"{n} of {n} job rows" in res.output and check.head in res.output
    assert _verify(pristine, "--head", check.head).exit_code == 0
    res = _verify(pristine, "--head", "0" * 64)
    assert res.exit_code == 1 and "not the one reported" in res.output
    assert _verify(pristine, "--head", "xyz").exit_code == 2
    assert _verify(tmp_path / "nothing").exit_code == 2
    ResultStore(tmp_path / "empty" / "results.sqlite").close()
    res = _verify(tmp_path / "empty")
    assert res.exit_code == 2 and "nothing to verify" in res.output


def test_the_report_leaves_the_edited_row_out_says_so_and_prints_the_head(pristine, tmp_path):
    from vbl_robust.report.build import build_report

    row = _raw(pristine, TARGETS["search"])
    run = _copy(pristine, tmp_path / "edited")
    _sql(run, "UPDATE jobs SET worst_m = 1.0 WHERE key = ?", (row["key"],))
    page = build_report(run, tmp_path / "html").read_text()
    first = page[page.index('id="safe-where-and-how-sure"'):]
    first = first[:first.index("</section>")]
    assert "inconsistent — not used" in first and "worst_m 1 stored" in first, first[:2000]
    with ResultStore.open_existing(pristine) as store:
        head = check_store(store).head
    assert f"vbl-robust verify RUN --head {head}" in page and "finding(s)" in page
    clean = build_report(pristine, tmp_path / "clean").read_text()
    assert "inconsistent — not used" not in clean and head in clean and "every row matches" in clean
    res = runner.invoke(app, ["report", str(run), "--format", "csv"])  # the summary rows say it, and exit 1
    assert res.exit_code == 1 and "1 job row(s) inconsistent — not used" in res.output, res.output
    assert runner.invoke(app, ["report", str(pristine), "--format", "csv"]).exit_code == 0


def test_a_deleted_sample_an_orphan_row_and_a_deleted_row_are_found(pristine, tmp_path):
    row = _raw(pristine, TARGETS["search"])
    gone = _copy(pristine, tmp_path / "sample")  # a sample row deleted: every row of that sample is an orphan
    _sql(gone, "DELETE FROM samples WHERE sample_id = ?", (row["sample_id"],))
    res = _verify(gone)
    with ResultStore.open_existing(gone) as store:
        check = screen(store)
        of_sample = {r["key"] for r in store.job_columns() if r["sample_id"] == row["sample_id"]}
        assert of_sample and not of_sample & {r.key for r in store.jobs()}
    assert res.exit_code == 1 and all(k in res.output for k in of_sample) and "not in the samples table" in res.output
    assert check.inconsistent == of_sample

    orphan = _copy(pristine, tmp_path / "orphan")  # a row of a sample the store never held, inserted by hand
    cols = ", ".join(c for c in JOB_COLUMNS if c not in ("key", "sample_id"))
    _sql(orphan, f"INSERT INTO jobs (key, sample_id, {cols}) SELECT 'orphan-row', 'synth_nowhere', {cols} FROM jobs "
                 "WHERE key = ?", (row["key"],))
    res = _verify(orphan)
    assert res.exit_code == 1 and "orphan-row: no digest" in res.output and "synth_nowhere" in res.output

    deleted = _copy(pristine, tmp_path / "deleted")  # a committed row deleted
    _sql(deleted, "DELETE FROM jobs WHERE key = ?", (row["key"],))
    res = _verify(deleted)
    assert res.exit_code == 1 and f"{row['key']}: deleted" in res.output


def test_a_resealed_digest_breaks_the_chain_and_a_resealed_store_changes_the_head(pristine, tmp_path):
    from vbl_robust.store.digest import row_digest

    row = _raw(pristine, TARGETS["search"])
    run = _copy(pristine, tmp_path / "forged")
    _sql(run, "UPDATE jobs SET worst_m = 1.0, verdict = 'no breach found' WHERE key = ?", (row["key"],))
    forged = _raw(run, f"key = '{row['key']}'")
    # the forger rewrites the row's digest entry too: the entry no longer follows its run's chain
    _sql(run, "UPDATE digests SET row_sha256 = ?, columns = ? WHERE key = ?", (*row_digest(forged), row["key"]))
    res = _verify(run)
    assert res.exit_code == 1 and f"{row['key']}: chain" in res.output
    # ... and the whole chain: verify agrees with itself, but the head differs from the one the report printed
    with ResultStore.open_existing(pristine) as store:
        head = check_store(store).head
    con = sqlite3.connect(run / "results.sqlite")
    with con:
        reseal(con)
    con.close()
    res = _verify(run, "--head", head)
    assert res.exit_code == 1 and "not the one reported" in res.output


def test_a_store_written_before_digests_still_gets_the_consistency_check(pristine, tmp_path):
    row = _raw(pristine, TARGETS["search"])
    old = _copy(pristine, tmp_path / "old")
    con = sqlite3.connect(old / "results.sqlite")
    with con:
        con.execute("DROP TABLE digests")
        con.execute("PRAGMA user_version = 4")
    con.close()
    res = _verify(old)
    assert res.exit_code == 0 and "no digests (rows written before schema 5)" in res.output, res.output
    _sql(old, "UPDATE jobs SET worst_m = 1.0 WHERE key = ?", (row["key"],))
    res = _verify(old)
    assert res.exit_code == 1 and f"{row['key']}: summary: worst_m 1 stored" in res.output
    assert "no digests" in res.output


def test_a_row_forgotten_and_run_again_keeps_the_store_verified(pristine, tmp_path):
    run = _copy(pristine, tmp_path / "forget")
    base = _raw(run, TARGETS["pnp"])
    failed = JobRow(key="not-measured-job", experiment=base["experiment"], kind="pnp", role="main", method="pnp",
                    sample_id=base["sample_id"], sample_index=base["sample_index"], status=JobStatus.NOT_MEASURED,
                    run_id=base["run_id"], reason="tool error: boom", verdict=Verdict.NOT_MEASURED, n_failed=0)
    with ResultStore(run / "results.sqlite") as store:
        store.commit([failed])
        assert check_store(store).ok
        assert store.forget_failed() == 1
        check = check_store(store)
        assert check.ok, check.findings
        store.commit([failed.replace(status=JobStatus.DONE, reason=None, verdict=None, payload={"redone": True})])
        assert check_store(store).ok
    _sql(run, "UPDATE jobs SET status = 'done', worst_m = 5000.0 WHERE key = 'not-measured-job'")
    assert _verify(run).exit_code == 1


def test_merge_leaves_inconsistent_rows_out_and_names_the_code_versions(pristine, tmp_path):
    row = _raw(pristine, TARGETS["search"])
    a = _copy(pristine, tmp_path / "a")
    _sql(a, "UPDATE jobs SET nfev = -5 WHERE key = ?", (row["key"],))
    _sql(a, "UPDATE runs SET code_version = '0.0.9'")
    res = runner.invoke(app, ["merge", str(a), "--into", str(tmp_path / "joined")])
    assert res.exit_code == 0, res.output
    assert "1 inconsistent — not merged" in res.output
    with ResultStore.open_existing(tmp_path / "joined") as store:
        assert row["key"] not in store.done_keys() and check_store(store).ok
        n = store.count()
    with ResultStore.open_existing(pristine) as store:
        assert n == store.count() - 1
        version = store.runs()[0].provenance.code_version
    res = runner.invoke(app, ["merge", str(pristine), "--into", str(tmp_path / "joined")])
    assert res.exit_code == 0 and f"code versions joined in {tmp_path / 'joined' / 'results.sqlite'}: 0.0.9, "
    assert f"0.0.9, {version}" in res.output, res.output
    report = merge_runs([pristine], tmp_path / "same")
    assert report.code_versions == (version,)


def test_zones_and_findings_are_typed(pristine, tmp_path):
    from vbl_robust.campaigns.replay import zones_of_run

    row = _raw(pristine, TARGETS["search"])
    run = _copy(pristine, tmp_path / "z")
    _sql(run, "UPDATE jobs SET worst_x_json = ? WHERE key = ?", (json.dumps({"roll_deg": 90.0}), row["key"]))
    assert row["key"] not in {j.key for j in zones_of_run(run)}
    with ResultStore.open_existing(run) as store:
        kinds = {f.kind for f in check_store(store).findings}
    assert kinds == {FindingKind.DIGEST, FindingKind.OUTSIDE_BOX, FindingKind.SUMMARY}


def test_risk_rows_agree_with_their_draws(tmp_path):
    from vbl_robust.campaigns.audit import risk_spec
    from vbl_robust.detect.shipped import DetectorSpec

    spec = risk_spec(roll_box(10), methods=("mc",), max_evals=32, guide_evals=8, seed=1)
    with ResultStore(tmp_path / "results.sqlite") as store:
        run_campaign(spec, generate(2, seed=3, width=96, height=96), store, detector=DetectorSpec.oracle(1.0))
        assert check_store(store).ok
    key = _raw(tmp_path, "kind = 'risk'")["key"]
    _sql(tmp_path, "UPDATE jobs SET worst_m = 1.0 WHERE key = ?", (key,))
    res = _verify(tmp_path)
    assert res.exit_code == 1 and f"{key}: summary: worst_m 1 stored" in res.output


def test_a_store_being_written_is_checked_as_it_stood(pristine, tmp_path, monkeypatch):
    """A row committed (with its digest) while a reader checks is not half seen: no 'no digest' finding."""
    import vbl_robust.campaigns.verify as verify

    run = _copy(pristine, tmp_path / "live")
    with ResultStore(run / "results.sqlite") as writer:  # open: its write-ahead log lies beside the store
        row = writer.jobs(kind="search", role="main", with_points=True)[0]
        read_chains = verify.read_chains

        def then_commit(entries):  # the digests read, then a writer commits a row before the rows are read
            chains = read_chains(entries)
            writer.commit([row.replace(key="committed-meanwhile")])
            return chains

        monkeypatch.setattr(verify, "read_chains", then_commit)
        with ResultStore.open_existing(run) as reader:
            check = check_store(reader)
        assert check.ok and "committed-meanwhile" not in {f.key for f in check.findings}, check.findings
        monkeypatch.undo()
        with ResultStore.open_existing(run) as reader:
            after = check_store(reader)
        assert after.ok and after.rows == check.rows + 1
