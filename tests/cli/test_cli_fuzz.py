"""Any combination of ``audit`` options, sensible or not, is either refused (exit 2, one error line, nothing
stored) or runs (exit 0): never a traceback, never a run that silently drops or reinterprets an option."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from vbl_robust.cli import app

runner = CliRunner()

#: option -> values to draw from (None: leave the option out); valid and invalid on purpose
POOL: dict[str, list[str | None]] = {
    "--roll": ["5", "-5", "0", "abc", "1,2", "2,1", "none", "inf"],
    "--contrast": [None, "0.8,1.2", "-1,2", "x"],
    "--perturb": [None, "haze=0,0.3", "haze=-1,1", "foo=1,2", "gamma", "roll_deg=1,2"],
    "--methods": ["random", "georobust", "random,random", "foo", "apgd", "grid"],
    "--max-evals": ["3", "0", "-1", "x"],
    "--pnp": [None, "ippe_lm", "foo"],
    "--lipschitz": [None, "100", "-1", "1,2,3"],
    "--sustain": [None, "2"],
    "--executor": [None, "local", "dask"],
    "--workers": [None, "1", "-3"],
    "--oracle-noise": [None, "0.5", "-1"],
    "--engine": [None, "torch", "tpu"],
}


def _audit_args(data, pool: dict[str, list[str | None]], out) -> list[str]:
    """A tiny oracle audit into ``out`` with one drawn value (or none) per option of ``pool``."""
    args = ["audit", "--oracle", "--n", "1", "--width", "64", "--height", "64", "--no-report", "--no-landscape",
            "--quiet", "--out", str(out)]
    for option, values in pool.items():
        value = data.draw(st.sampled_from(values), label=option)
        if value is not None:
            args += [option, value]
    return args


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_option_combination_is_refused_in_one_line_or_runs(tmp_path_factory, data):
    out = tmp_path_factory.mktemp("fuzz") / "run"
    args = _audit_args(data, POOL, out)
    res = runner.invoke(app, args)
    text = res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), (args, repr(res.exception))
    assert "Traceback" not in text, (args, text)
    assert res.exit_code in (0, 2), (args, res.exit_code, text)
    if res.exit_code == 2:
        errors = [ln for ln in text.splitlines() if ln.lower().startswith("error")]
        assert len(errors) == 1, (args, text)
        assert not (out / "results.sqlite").exists(), (args, text)  # refused before any work


VALID: dict[str, list[str | None]] = {
    "--roll": ["5", "1,2", "none"], "--contrast": [None, "0.8,1.2"], "--perturb": ["haze=0,0.3", "gamma"],
    "--methods": ["random", "georobust", "grid", "random,georobust-av"], "--max-evals": ["3", "5"],
    "--pnp": [None, "ippe_lm", "iterative"], "--lipschitz": [None, "100"], "--executor": [None, "local"],
    "--workers": [None, "1"], "--oracle-noise": [None, "0.5"],
}


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_valid_combination_runs(tmp_path_factory, data):
    out = tmp_path_factory.mktemp("valid") / "run"
    args = _audit_args(data, VALID, out)
    res = runner.invoke(app, args)
    assert res.exit_code == 0 and (out / "results.sqlite").exists(), (args, res.output)
