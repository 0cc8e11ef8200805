"""benchmarks/measure_harden.py and harden_tradeoff.py: one command each, every step skipped when its outputs are
there (dry runs: the commands they would run)."""

from __future__ import annotations

from pathlib import Path


def _names(commands: list[list[str]]) -> list[str]:
    return [c[1] if Path(c[0]).name == "vbl-robust" else Path(c[1]).name for c in commands]


def test_the_measurement_runs_what_is_missing_and_nothing_else(script, tmp_path, monkeypatch):
    m = script("benchmarks/measure_harden.py")
    # a new checkout: the paper's packed spatial-1d store is there, its run directory not (restored first)
    monkeypatch.setattr(m, "ROOT", tmp_path)
    (tmp_path / "results" / "paper" / "spatial-1d").mkdir(parents=True)
    (tmp_path / "results" / "paper" / "spatial-1d" / "results.sqlite.xz").write_bytes(b"")
    monkeypatch.setattr(m, "RES", tmp_path / "res")
    monkeypatch.setattr(m, "SHIPPED", tmp_path / "shipped.pt")
    s = m.Steps(dry_run=True)
    m.measure(s, tmp_path / "h", tmp_path / "audits", tmp_path / "keep")
    assert _names(s.commands) == ["harden", "detector_protocol.py", "ship",
                                  *["merge", "reproduce", "bundle", "report", "report"],
                                  *(["audit", "audit", "bundle", "report", "report"] * 2)]
    harden = s.commands[0]
    assert harden[2:] == [*m.TRAINING, "--trust-model", "--out", str(tmp_path / "h")]  # resumes its own rounds
    assert s.commands[1][s.commands[1].index("--model") + 1] == f"<weights of {tmp_path / 'h'}/round01>"
    # once the model is shipped and measured and an audit's comparison is written, those steps are skipped
    (tmp_path / "shipped.pt").write_bytes(b"")
    (tmp_path / "res").mkdir()
    for name in ("protocol_all.json", "box2d_compare.md"):
        (tmp_path / "res" / name).write_text("")
    (tmp_path / "keep" / "box2d_hardened").mkdir(parents=True)
    (tmp_path / "keep" / "box2d_hardened" / "compare.html").write_text("")
    (tmp_path / "runs" / "paper" / "spatial-1d").mkdir(parents=True)
    (tmp_path / "runs" / "paper" / "spatial-1d" / "results.sqlite").write_bytes(b"")  # restored before
    s = m.Steps(dry_run=True)
    m.measure(s, tmp_path / "h", tmp_path / "audits", tmp_path / "keep")
    assert _names(s.commands) == ["reproduce", "bundle", "report", "report", "audit", "audit", "bundle", "report",
                                  "report"]
    assert "brightness=-0.2,0.2" in s.commands[4]


def test_the_tradeoff_runs_only_the_tries_it_lacks(script, tmp_path, monkeypatch):
    t = script("benchmarks/harden_tradeoff.py")
    m = script("benchmarks/measure_harden.py")
    monkeypatch.setattr(t, "TRIES", tuple((name, tmp_path / name, opts) for name, _, opts in t.TRIES))
    res = tmp_path / "res"
    res.mkdir()
    for name in ("try1", "try3"):
        for r in (0, 1):
            (res / f"{name}_r{r}_validation.json").write_text("")
            (res / f"screen_{name}_r{r}_compare.md").write_text("")
    for r in (0, 1):  # try2 trained already: its rounds are read back
        (tmp_path / "try2" / f"round0{r}").mkdir(parents=True)
        (tmp_path / "try2" / f"round0{r}" / "round.json").write_text(
            f'{{"index": {r}, "weights": "{tmp_path}/try2/w{r}.pt", "worst": [], "values": [], "breaches": 0}}')
    s = m.Steps(dry_run=True)
    t.tradeoff(s, tmp_path / "runs", res)
    assert _names(s.commands) == ["reproduce", *(["detector_protocol.py", "reproduce", "report"] * 2)]
    assert s.commands[0][-3:] == ["default", "--out", str(tmp_path / "runs" / "screen_v9")]
    models = [c[c.index("--model") + 1] for c in s.commands if "--model" in c]
    assert models == ["default", *[f"{tmp_path}/try2/w{r}.pt" for r in (1, 1, 0, 0)]]  # last round first
