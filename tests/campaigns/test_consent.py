"""No code from data without consent: a results store whose campaign names a detector that is code (a factory's
``module:callable``, a ``.pt`` outside the package) is refused by every command that would build it or pass it on,
unless ``--trust-model``; the payload tests fail if the stored code runs."""

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vbl_robust.cli import app
from vbl_robust.consent import CODE_KINDS, consent_needed, refuse_without_consent
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.store.core import ResultStore
from vbl_robust.store.pack import pack_store

runner = CliRunner()


class MarkingOracle(OracleDetector):
    """A harmless factory: the oracle, leaving ``marker`` behind when built (consent given: it IS built)."""

    def __init__(self, marker: str, **kw):
        super().__init__(**kw)
        Path(marker).touch()


def _payload(marker: Path) -> dict:
    """A detector identity that runs a shell command when built (what a crafted store can hold)."""
    return {"kind": "factory", "factory": "subprocess:run", "name": "factory: subprocess:run", "path": None,
            "sha256": None, "options": {"args": f"touch {marker}", "shell": True}}


def _with_detector(run: Path, ident: dict) -> Path:
    con = sqlite3.connect(run / "results.sqlite")
    try:
        con.execute("UPDATE campaign SET detector_json = ? WHERE id = 1", (json.dumps(ident),))
        con.commit()
    finally:
        con.close()
    return run


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """A small oracle run (two images, every job surviving)."""
    out = tmp_path_factory.mktemp("consent") / "run"
    res = runner.invoke(app, ["audit", "--out", str(out), "--n", "2", "--roll", "5", "--methods", "random",
                              "--max-evals", "2", "--oracle", "--width", "96", "--height", "96", "--workers", "1",
                              "--no-landscape", "--no-report", "-q"])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture
def evil(clean, tmp_path):
    """``clean`` with its campaign's detector replaced by the payload; the marker it would touch."""
    marker = tmp_path / "MARKER"
    run = _with_detector(Path(shutil.copytree(clean, tmp_path / "evil")), _payload(marker))
    return run, marker


def _refused(res, marker: Path, *words: str) -> None:
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1 and "Traceback" not in res.output, res.output
    assert "--trust-model" in res.output and all(w in res.output for w in words), res.output
    assert not marker.exists(), "the stored code ran"


def test_one_function_decides_what_needs_consent(tmp_path):
    assert "plugin" in CODE_KINDS  # --detector-plugin goes through it too
    for kind in CODE_KINDS:
        why = consent_needed({"kind": kind, "factory": "os:system", "options": {}})
        assert why and "'os'" in why and "'system'" in why and "\n" not in why
    assert consent_needed(DetectorSpec("factory", "campaign_helpers:SlowOracle"))
    assert consent_needed({"kind": "ultralytics", "path": str(tmp_path / "m.pt")}).endswith("runs code when loaded")
    assert consent_needed({"kind": "ultralytics", "path": None})
    shipped = Path(__file__).resolve().parents[2] / "src/vbl_robust/models/runway_yolov8n_pose.pt"
    assert consent_needed({"kind": "ultralytics", "path": str(shipped)}) is None  # the package's own file
    for ident in ({"kind": "oracle"}, {"kind": "default"}, {"kind": "onnx", "path": str(tmp_path / "m.onnx")}):
        assert consent_needed(ident) is None
    refuse_without_consent({"kind": "factory", "factory": "os:system"}, True)  # consent given
    with pytest.raises(ValueError, match=r"^RUN: detector factory 'os:system' is code.*pass --trust-model"):
        refuse_without_consent({"kind": "factory", "factory": "os:system"}, False, where="RUN: ")


def test_from_identity_refuses_code_before_any_import(tmp_path):
    marker = tmp_path / "MARKER"
    with pytest.raises(ValueError, match=r"^S: detector factory 'subprocess:run' is code.*--trust-model"):
        DetectorSpec.from_identity(_payload(marker), where="S: ")
    with pytest.raises(ValueError, match="not_a_module_anywhere"):  # refused before the import is tried
        DetectorSpec.from_identity({"kind": "factory", "factory": "not_a_module_anywhere:x"})
    with pytest.raises(ValueError, match=r"m\.pt: a \.pt file is a pickle"):
        DetectorSpec.from_identity({"kind": "ultralytics", "path": str(tmp_path / "m.pt")})
    with pytest.raises(ValueError, match="plug-in|plugin"):  # a kind this version does not know: still refused
        DetectorSpec.from_identity({"kind": "plugin", "factory": "os:system"})
    spec = DetectorSpec.from_identity(_payload(marker), trust=True)  # consent: named, not yet built
    assert (spec.kind, spec.path) == ("factory", "subprocess:run") and not marker.exists()
    assert DetectorSpec.from_identity({"kind": "oracle", "options": {"noise_px": 1.0}}) == DetectorSpec.oracle(1.0)
    with pytest.raises(ValueError, match="options are not a mapping"):
        DetectorSpec.from_identity({"kind": "oracle", "options": [1]})


def test_truth_refuses_a_stored_factory_and_builds_it_with_consent(evil, tmp_path):
    run, marker = evil
    res = runner.invoke(app, ["truth", str(run), "--counts", "3", "--workers", "1", "--no-report", "-q"])
    _refused(res, marker, str(run), "subprocess:run")
    assert not run.with_name(run.name + "-truth").exists()
    built = tmp_path / "BUILT"  # consent: the (harmless) factory is built and the grid runs
    _with_detector(run, {"kind": "factory", "factory": "test_consent:MarkingOracle", "name": "marking",
                         "options": {"marker": str(built)}})
    res = runner.invoke(app, ["truth", str(run), "--counts", "3", "--workers", "1", "--no-report", "-q"])
    assert res.exit_code == 2 and "test_consent:MarkingOracle" in res.output and not built.exists(), res.output
    res = runner.invoke(app, ["truth", str(run), "--counts", "3", "--workers", "1", "--no-report", "-q",
                              "--trust-model"])
    assert res.exit_code == 0, res.output
    assert built.exists()
    with ResultStore.open_existing(run.with_name(run.name + "-truth")) as st:
        assert st.count() == 2


def test_a_config_file_cannot_consent(evil, tmp_path):
    run, marker = evil
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("trust_model: true\n")  # e.g. a config.yaml that came with the store
    res = runner.invoke(app, ["truth", str(run), "--counts", "3", "--workers", "1", "--no-report", "-q",
                              "--config", str(cfg)])
    _refused(res, marker, "a --config file cannot consent")


def test_merge_refuses_a_stored_factory_and_writes_nothing(evil, clean, tmp_path):
    run, marker = evil
    into = tmp_path / "joined"
    res = runner.invoke(app, ["merge", str(run), "--into", str(into)])
    _refused(res, marker, str(run), "subprocess:run")
    assert not into.exists()
    res = runner.invoke(app, ["merge", str(clean), "--into", str(into)])  # a clean run joins; then the payload
    assert res.exit_code == 0, res.output
    before = (into / "results.sqlite").read_bytes()
    res = runner.invoke(app, ["merge", str(run), "--into", str(into)])
    _refused(res, marker, "subprocess:run")
    assert (into / "results.sqlite").read_bytes() == before
    with ResultStore.open_existing(run) as st:  # packed, as a bundle carries it
        packed = pack_store(st, tmp_path / "evil.sqlite.xz")
    res = runner.invoke(app, ["merge", str(packed), "--into", str(tmp_path / "other")])
    _refused(res, marker, "evil.sqlite.xz")
    assert not (tmp_path / "other").exists()
    res = runner.invoke(app, ["merge", str(run), "--into", str(tmp_path / "trusted"), "--trust-model"])
    assert res.exit_code == 0 and "2 job rows merged" in res.output, res.output
    assert not marker.exists()  # a merge copies rows: it never builds the detector


def test_a_damaged_points_blob_is_one_line_in_merge(clean, tmp_path):
    src = Path(shutil.copytree(clean, tmp_path / "damaged"))
    for blob in (b"abcd", __import__("zlib").compress(b'{"xs": 1}')):
        con = sqlite3.connect(src / "results.sqlite")
        con.execute("UPDATE jobs SET points = ? WHERE rowid = (SELECT min(rowid) FROM jobs)", (blob,))
        con.commit()
        con.close()
        into = tmp_path / f"into-{len(blob)}"
        res = runner.invoke(app, ["merge", str(src), "--into", str(into)])
        assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output
        assert "cannot be decoded" in res.output and str(src) in res.output and "Traceback" not in res.output
        with ResultStore.open_existing(into) as st:
            assert st.count() == 0 and st.campaign() is None  # nothing merged, the campaign not bound either


def test_reproduce_resume_from_refuses_a_bundle_holding_a_factory(evil, tmp_path):
    run, marker = evil
    bundle = tmp_path / "bundle"
    (bundle / "spatial-1d").mkdir(parents=True)
    with ResultStore.open_existing(run) as st:
        pack_store(st, bundle / "spatial-1d" / "results.sqlite.xz")
    out = tmp_path / "out"
    args = ["reproduce", "spatial-1d", "--resume-from", str(bundle), "--out", str(out), "--images", "1", "--oracle",
            "--width", "96", "--height", "96", "--max-evals", "2", "--grid-step", "0", "--workers", "1",
            "--no-report", "-q"]
    res = runner.invoke(app, args)
    _refused(res, marker, "--resume-from", "spatial-1d", "subprocess:run")
    assert not out.exists()
    res = runner.invoke(app, [*args, "--trust-model"])  # consent: restored, then refused as another detector
    assert "store restored" in res.output and not marker.exists(), res.output


def test_reading_a_stored_factory_runs_nothing(evil):
    run, marker = evil
    for args in (["zones", str(run), "--format", "md"], ["report", str(run), "--format", "csv"]):
        res = runner.invoke(app, args)
        assert res.exit_code == 0, res.output
        assert not marker.exists()
