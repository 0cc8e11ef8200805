"""Issue 48 item 5: counts, sizes and grids have stated bounds, checked before any work (one line, exit 2, nothing
stored), and a stored blob may not inflate past its bound."""

import zlib

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.constants import MAX_GRID_POINTS

runner = CliRunner()


@pytest.mark.parametrize(("args", "msg"), [
    (["audit", "--seed", "9223372036854775808"], "--seed"),
    (["audit", "--width", "100000"], "--width"),
    (["audit", "--images", "1000000000"], "--images"),
    (["scenes", "--n", "1000000000"], "--n"),
    (["demo", "--images", "1000000000"], "--images"),
    (["audit", "--max-evals", "100000000000"], "--max-evals"),
    (["audit", "--methods", "grid", "--method-option", "grid.counts=[1000000000]"], f"bound of {MAX_GRID_POINTS}"),
    (["reproduce", "spatial-1d", "--grid-step", "1e-12", "--images", "1"], f"bound of {MAX_GRID_POINTS}"),
])
def test_a_count_beyond_its_bound_is_refused_before_any_work(tmp_path, args, msg):
    out = tmp_path / "run"
    res = runner.invoke(app, [*args, "--out", str(out), *(["--oracle"] if args[0] != "scenes" else [])])
    assert res.exit_code == 2 and msg in res.output, res.output
    assert not (out / "results.sqlite").exists()


def test_a_stored_blob_may_not_inflate_past_its_bound(monkeypatch):
    from vbl_robust.store import rows

    monkeypatch.setattr(rows, "MAX_BLOB_BYTES", 1000)
    bomb = zlib.compress(b"[" + b"0," * 5000 + b"0]")  # tiny compressed, 10 kB inflated
    with pytest.raises(ValueError, match="decompresses to more than 1000 bytes"):
        rows.Points.from_blob(bomb)


def test_probes_that_gave_tracebacks_give_one_line(tmp_path):
    """Issue 48 item 9: each of these printed a traceback; now one line naming the option, exit 2."""
    import lzma

    (tmp_path / "file").write_text("x")
    cut = tmp_path / "cut" / "spatial-1d"
    cut.mkdir(parents=True)
    (cut / "results.sqlite.xz").write_bytes(lzma.compress(b"y" * 5000)[:30])
    probes = [
        (["reproduce", "runtime-1d", "--time-budgets", "nan", "--out", str(tmp_path / "r"), "--oracle"],
         "--time-budgets"),
        (["reproduce", "spatial-1d", "--resume-from", str(tmp_path / "cut"), "--out", str(tmp_path / "r2"),
          "--oracle", "--images", "1"], "not a complete packed store"),
        (["bundle", str(tmp_path), "--out", str(tmp_path / "file")], "is a file"),
        (["train", "--imgsz", "0", "--out", str(tmp_path / "t")], "--imgsz"),
    ]
    for args, msg in probes:
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and msg in res.output and "Traceback" not in res.output, (args, res.output)
