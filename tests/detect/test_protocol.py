"""The detector protocol (:mod:`vbl_robust.detect.protocol`) and ``vbl-robust ship``: default.json's note, gate and
open goals from a protocol JSON, and the replacement rule."""

from __future__ import annotations

import json

from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.detect import protocol as tool


def _rows(det, surv, far, err, n=510):
    return [{"envelope": "far", "n": n // 3, "survival_ippe_lm": far, "detection_rate": det,
             "pos_err_pct_ippe_lm": err},
            {"envelope": "all", "n": n, "survival_ippe_lm": surv, "detection_rate": det, "pos_err_pct_ippe_lm": err}]


def test_validation_pools_its_seeds_and_test_misses_become_open_goals():
    p = {"validation": {"1": _rows(0.99, 0.93, 0.87, 7.0), "2": _rows(0.97, 0.86, 0.70, 7.5, n=1020)},
         "test": {"7": _rows(0.99, 0.88, 0.64, 7.4), "8": _rows(0.995, 0.92, 0.80, 6.9)}}
    info = tool.info_from_protocol(p, version=8, epochs=46)
    # pooled: survival (0.93·510 + 0.86·1020) / 1530 = 88.3 % < 90 %: the validation gate fails
    assert info["validated"] is False
    assert "seeds 1, 2, 1530 approaches" in info["note"] and "survival 88.3 %" in info["note"]
    assert any("below the 90 % gate on seed 7 (far approaches 64.0 %)" in g for g in info["open_goals"])
    assert any("goal 5 %" in g for g in info["open_goals"])
    p["validation"]["2"] = _rows(0.98, 0.92, 0.80, 7.0)
    assert tool.info_from_protocol(p, version=8, epochs=46)["validated"] is True


def test_replacement_needs_a_significant_paired_gain():
    """The replacement rule: more pooled validation approaches survive and the paired exact test gives p < 0.05."""
    old = {"validation": {"1": [], "2": []}, "survived": {"1": [True] * 90 + [False] * 10,
                                                          "2": [True] * 90 + [False] * 10}}
    # seed 1: 10 approaches gained, 3 lost (+7 of 13 discordant): p ≈ 0.09, not significant
    small = {"validation": {"1": [], "2": []},
             "survived": {"1": [True] * 87 + [False] * 3 + [True] * 10, "2": [True] * 90 + [False] * 10}}
    # 20 approaches gained, none lost: p = 2 · 0.5^20
    big = {"validation": {"1": [], "2": []},
           "survived": {"1": [True] * 100, "2": [True] * 100}}
    ok, why = tool.replacement_verdict(small, old)
    assert not ok and "only with the candidate" in why and "+7" in why
    ok, why = tool.replacement_verdict(big, old)
    assert ok and "+20" in why and "p = 0.000" in why
    assert tool.replacement_verdict(old, big)[0] is False  # a significant loss is no replacement
    ok, why = tool.replacement_verdict(big, {"validation": {"1": []}})
    assert not ok and "per-approach" in why


def test_ship_refuses_before_writing_anything(tmp_path):
    """No --against without --force, a rule not met, an untrusted pickle: refused in one line, the model untouched."""
    from vbl_robust.detect.shipped import DEFAULT_MODEL

    before = DEFAULT_MODEL.read_bytes()
    ckpt = tmp_path / "c.pt"
    ckpt.write_bytes(b"not read")
    old = {"validation": {"1": []}, "survived": {"1": [True] * 90 + [False] * 10}}
    same = {"validation": {"1": []}, "survived": {"1": [True] * 90 + [False] * 10}}
    (tmp_path / "old.json").write_text(json.dumps(old))
    (tmp_path / "new.json").write_text(json.dumps(same))
    base = ["ship", str(ckpt), "--version", "10", "--epochs", "3", "--protocol", str(tmp_path / "new.json")]
    runner = CliRunner()
    for args, message in ((base, "pass --trust-model"),
                          ([*base, "--trust-model"], "--against SHIPPED.json is required"),
                          ([*base, "--trust-model", "--against", str(tmp_path / "old.json")], "not shipped"),
                          ([*base[:-1], str(tmp_path / "none.json"), "--trust-model", "--force"], "--protocol/--against")):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and message in res.output, (args, res.output)
    assert DEFAULT_MODEL.read_bytes() == before
    assert tool.VALIDATION_SEEDS[0] == 20_261_122 and not set(tool.VALIDATION_SEEDS) & set(tool.TEST_SEEDS)
