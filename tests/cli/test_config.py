"""A run described by a file: --config FILE gives the options (the command line overrides them), every run
directory keeps its full configuration as config.yaml, and that file repeats the run."""

import sqlite3

import pytest
import yaml
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()


def _jobs(run):
    with sqlite3.connect(run / "results.sqlite") as con:
        return con.execute("SELECT count(*) FROM jobs").fetchone()[0]


def test_a_campaign_file_runs_the_command_line_overrides_it_and_the_run_keeps_its_configuration(tmp_path,
                                                                                              monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "campaign.yaml").write_text(
        "command: audit\nn: 1\nmax-evals: 6\nmethods: random\noracle: true\noracle_noise: 0.5\nwidth: 96\n"
        "height: 96\nperturb: [blur_px]\nearly-stop: false\nlandscape: false\nout: runs/a\n")
    res = runner.invoke(app, ["-q", "audit", "--config", "campaign.yaml", "--max-evals", "8"])
    assert res.exit_code == 0, res.output
    kept = yaml.safe_load((tmp_path / "runs/a/config.yaml").read_text())
    assert kept["command"] == "audit" and kept["max_evals"] == 8 and kept["n"] == 1  # the override, the file
    assert kept["perturb"] == ["blur_px"] and kept["early_stop"] is False and kept["seed"] == 0  # and a default
    assert "config" not in kept and "quiet" not in kept
    with sqlite3.connect(tmp_path / "runs/a/results.sqlite") as con:
        assert {r[0] for r in con.execute("SELECT nfev FROM jobs")} == {8}  # the command line won
    done = _jobs(tmp_path / "runs/a")
    again = runner.invoke(app, ["-q", "audit", "--config", "runs/a/config.yaml"])  # repeats it: nothing new to run
    assert again.exit_code == 0 and f"0 new jobs, {done} already done" in again.output, again.output
    fresh = runner.invoke(app, ["-q", "audit", "--config", "runs/a/config.yaml", "--out", "runs/b"])
    assert fresh.exit_code == 0 and _jobs(tmp_path / "runs/b") == done


@pytest.mark.parametrize("text, message", [
    ("foo: 1\n", "'foo' is not an option of audit"),
    ("command: risk\n", "a configuration for 'risk', not 'audit'"),
    ("[1, 2]\n", "expected a mapping of option names to values"),
    ("max-evals: [oops\n", "not YAML"),
    ("quiet: true\n", "'quiet' is not an option of audit"),
    ("max_evals: abc\n", "Invalid value for '--max-evals'"),
])
def test_a_bad_campaign_file_is_refused_in_one_line_before_any_work(tmp_path, text, message):
    (tmp_path / "c.yaml").write_text(text)
    res = runner.invoke(app, ["audit", "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output
    assert not (tmp_path / "run").exists()


def test_every_campaign_command_takes_a_file():
    for command in ("audit", "demo", "risk", "reproduce", "truth"):
        res = runner.invoke(app, [command, "--help"])
        assert res.exit_code == 0 and "--config" in res.output, command


def test_the_campaign_files_in_the_documentation_name_real_options(tmp_path):
    """Each YAML block of docs/how-to/config.md reads as a configuration of its command (keys and command)."""
    import re
    from pathlib import Path

    import typer

    from vbl_robust.cli.config import read_config
    from vbl_robust.perturb.registry import PERTURBATIONS

    page = Path(__file__).resolve().parents[2] / "docs" / "how-to" / "config.md"
    blocks = re.findall(r"```yaml\n(.*?)```", page.read_text(), flags=re.S)
    assert len(blocks) >= 4
    group = typer.main.get_command(app)
    for i, text in enumerate(blocks):
        command = yaml.safe_load(text)["command"]
        path = tmp_path / f"{i}.yaml"
        path.write_text(text)
        options = read_config(path, command, group.commands[command].params)
        assert options, text
        for item in options.get("perturb", []):  # a flow list splits at commas: "haze=0,0.3" must be quoted
            assert item.split("=")[0] in PERTURBATIONS, (item, text)


BOMB = ('a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n'
        + "".join(f"{k}: &{k} [{','.join([f'*{p}'] * 9)}]\n" for p, k in zip("abcdefgh", "bcdefghi", strict=True)))


@pytest.mark.parametrize("text, message", [
    (BOMB, "expand past 1048576 bytes through YAML aliases"),
    ("perturb: &p [blur_px, *p]\n", "a recursive alias"),
    ("seed: true\n", "'seed': expected an integer, got the boolean true"),
    ("oracle_noise: yes\n", "'oracle_noise': expected a number, got the boolean true"),
    ("out: false\n", "'out': expected a value, got the boolean false"),
    ("seed: 1.5\n", "'seed': expected an integer, got 1.5"),
    ("seed: [1, 2]\n", "'seed': expected one value, got a list"),
    ("seed: {a: 1}\n", "'seed': expected one value, got a mapping"),
    ("oracle: 1\n", "'oracle': a flag takes true or false, got 1"),
    ("seed: 1\nseed: 2\n", "line 2: key 'seed' given twice"),
    ("n: 2\nimages: 3\n", "'n' and 'images' name the same option (n); give it once"),
    ("design: auto\ndetector: single\n", "'design' and 'detector' name the same option (detector)"),
    ("[" * 100_000 + "\n", "not YAML"),
    ("seed: !!python/object/apply:os.system [echo hi]\n", "not YAML"),
])
def test_a_campaign_file_is_read_within_bounds_and_strictly(tmp_path, text, message):
    import time

    (tmp_path / "c.yaml").write_text(text)
    t0 = time.perf_counter()
    res = runner.invoke(app, ["audit", "--config", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")])
    assert time.perf_counter() - t0 < 10
    assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output
    assert not (tmp_path / "run").exists()


def test_a_file_that_is_not_a_regular_utf8_file_is_refused_in_one_line(tmp_path):
    (tmp_path / "latin1.yaml").write_bytes("seed: 1\nroll: '15'  # ±\n".encode("latin-1"))
    for path, message in (("/dev/zero", "not a regular file"), (str(tmp_path), "not a regular file"),
                          (str(tmp_path / "latin1.yaml"), "not UTF-8 text (byte 0xb1 on line 2)"),
                          (str(tmp_path / "nothing.yaml"), "No such file or directory")):
        res = runner.invoke(app, ["audit", "--config", path, "--out", str(tmp_path / "run")])
        assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output, res.output
    big = tmp_path / "big.yaml"
    big.write_text("# " + "x" * (1 << 20) + "\n")
    res = runner.invoke(app, ["audit", "--config", str(big)])
    assert res.exit_code == 2 and "larger than 1048576 bytes" in res.output, res.output


def test_keys_are_the_options_as_spelt_with_the_parameter_names_as_aliases(tmp_path):
    import typer

    from vbl_robust.cli.config import read_config

    params = typer.main.get_command(app).commands["audit"].params
    (tmp_path / "c.yaml").write_text("detector: twostage\nimages: 3\nmax-evals: 5\nearly_stop: false\n"
                                     "perturb: blur_px\n")
    assert read_config(tmp_path / "c.yaml", "audit", params) == {
        "design": "twostage", "n": 3, "max_evals": 5, "early_stop": False, "perturb": ["blur_px"]}
    (tmp_path / "c.yaml").write_text("design: single\nn: 2\n")  # the parameter names, as older files have them
    assert read_config(tmp_path / "c.yaml", "audit", params) == {"design": "single", "n": 2}
