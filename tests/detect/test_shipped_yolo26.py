"""The optional shipped detector ``--model yolo26`` (issue 60): v9's pass 1 with the YOLO26-pose crop network U2
as pass 2, whose per-corner σ the σ monitor reads; v9 stays the default."""

from __future__ import annotations

import numpy as np
import pytest

from vbl_robust.detect.shipped import DEFAULT_MODEL, DetectorSpec, default_model_path
from vbl_robust.detect.twostage import TwoStageDetector
from vbl_robust.digest import file_sha256
from vbl_robust.pipeline import Objective
from vbl_robust.scenes.generate import generate
from vbl_robust.space import ParameterBox


def test_yolo26_is_shipped_two_stage_behind_v9s_pass_1_and_not_the_default():
    spec = DetectorSpec.from_choice("yolo26")
    ident = spec.identity()
    assert ident["design"] == "two-stage" and ident["input_size"] == 320
    assert ident["first_sha256"] == file_sha256(DEFAULT_MODEL)  # pass 1 is v9's network, part of the identity
    assert ident["sha256"] == file_sha256(default_model_path("yolo26")) != ident["first_sha256"]
    assert spec.key() != DetectorSpec.from_choice("default").key()
    assert DetectorSpec.choose()[0].shipped_name == "default"  # v9 stays the default
    det = spec.build()
    assert isinstance(det, TwoStageDetector) and det.second is not det.first and det.gives_sigma
    assert det.first.path == DEFAULT_MODEL


@pytest.mark.slow
def test_yolo26_gives_a_position_sigma_on_a_rendered_approach():
    sample = generate(1, seed=3, width=512, height=512)[0]
    box = ParameterBox({"roll_deg": (-5, 5)})
    rec = Objective(sample, DetectorSpec.from_choice("yolo26").build(), box).evaluate(np.zeros((1, 1)))
    assert rec.keypoint_sigma is not None and np.isfinite(rec.position_sigma_m).all()


def test_yolo26_refuses_the_single_pass_design():
    with pytest.raises(ValueError, match="pass-2 \\(crop\\) network behind 'default': it runs two-stage only"):
        DetectorSpec.from_choice("yolo26", design="single").build()
