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
