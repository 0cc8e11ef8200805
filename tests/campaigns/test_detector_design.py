"""``--detector single|twostage``: the design of a model detector, carried by the spec (and its key)."""

import pytest
from typer.testing import CliRunner

from vbl_robust.campaigns.provenance import DetectorSpec
from vbl_robust.cli import app
from vbl_robust.cli.common import detector_spec
from vbl_robust.detect.shipped import DEFAULT_MODEL, with_design
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.detect.ultralytics import UltralyticsDetector


@pytest.mark.skipif(not DEFAULT_MODEL.exists(), reason="no shipped model")
def test_shipped_model_in_either_design():
    one = DetectorSpec("default", options={"design": "single"})
    two = DetectorSpec("default", options={"design": "twostage"})
    assert type(one.build()) is UltralyticsDetector
    assert isinstance(two.build(), TwoStageDetector)
    assert one.key() != two.key()  # results of the two designs never mix in a store


def test_with_design_wraps_or_refuses():
    det = UltralyticsDetector(DEFAULT_MODEL, trust=True) if DEFAULT_MODEL.exists() else None
    if det is not None:
        assert with_design(det, "single") is det
        assert isinstance(with_design(det, "twostage"), TwoStageDetector)
    with pytest.raises(ValueError, match="design"):
        with_design(det, "three-stage")


def test_cli_spec_for_each_design(tmp_path):
    assert detector_spec(None, False, True, 0.0).kind == "oracle"
    spec = detector_spec("default", False, False, 0.0, "single")
    assert spec.kind == "default" and spec.options == {"design": "single"}
    pt = tmp_path / "mine.pt"
    pt.write_bytes(b"x")
    spec = detector_spec(pt, True, False, 0.0, "twostage")
    assert spec.kind == "ultralytics" and spec.trust and spec.options == {"design": "twostage"}


def test_cli_rejects_design_with_the_oracle_and_unknown_designs():
    runner = CliRunner()
    res = runner.invoke(app, ["audit", "--oracle", "--detector", "single", "--images", "1"])
    assert res.exit_code == 2 and "--detector" in res.output
    res = runner.invoke(app, ["audit", "--detector", "triple", "--images", "1"])
    assert res.exit_code == 2 and "triple" in res.output
