from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()


def test_train_refuses_untrusted_init_pickle(tmp_path):
    pt = tmp_path / "someone_elses.pt"
    pt.write_bytes(b"not really a pickle")
    res = runner.invoke(app, ["train", "--init", str(pt), "--out", str(tmp_path / "run")])
    assert res.exit_code == 2
    assert "--trust-model" in res.output
    assert not (tmp_path / "run").exists()


def test_train_names_missing_init_file(tmp_path):
    res = runner.invoke(app, ["train", "--init", str(tmp_path / "missing.pt"), "--out", str(tmp_path / "run")])
    assert res.exit_code == 2
    assert "missing.pt" in res.output and "not found" in res.output


def test_train_names_bad_lard_directory(tmp_path):
    res = runner.invoke(app, ["train", "--lard", str(tmp_path / "nope"), "--out", str(tmp_path / "run")])
    assert res.exit_code == 2
    assert "nope" in res.output


def test_train_passes_the_training_levers(tmp_path, monkeypatch):
    from vbl_robust.detect import train as tr

    seen = {}

    def fake_train(out, **kw):
        seen.update(kw)
        return tr.TrainResult(out / "stage00", out / "best.pt", out / "last.pt", False)

    monkeypatch.setattr(tr, "train", fake_train)
    res = runner.invoke(app, ["train", "--out", str(tmp_path), "--crops", "3", "--crops-used", "1", "--min-box", "16",
                              "--lr0", "0.001", "--optimizer", "AdamW", "--workers", "0", "--imgsz", "480"])
    assert res.exit_code == 0, res.output
    assert seen["crops_per_sample"] == 3 and seen["crops_used"] == 1 and seen["min_box"] == 16
    assert seen["lr0"] == 0.001 and seen["optimizer"] == "AdamW" and seen["workers"] == 0 and seen["imgsz"] == 480
    assert seen["threads"] is None and seen["full_views"] is True
    res = runner.invoke(app, ["train", "--out", str(tmp_path), "--crops-only"])
    assert res.exit_code == 0, res.output
    assert seen["full_views"] is False


def test_train_refuses_an_unknown_optimizer_before_any_work(tmp_path):
    res = runner.invoke(app, ["train", "--optimizer", "foo", "--out", str(tmp_path / "run"), "--epochs", "1"])
    assert res.exit_code == 2 and "optimizer must be one of auto, SGD" in res.output and "'foo'" in res.output
    assert not (tmp_path / "run").exists()
