"""The detector protocol's pooled validation row and its seed sets (the figures every detector choice rests on)."""

from __future__ import annotations

import pytest


def _rows(n_far, far, n_all, all_, det=1.0):
    return [{"envelope": "far", "n": n_far, "survival_ippe_lm": far, "detection_rate": det},
            {"envelope": "medium", "n": 1, "survival_ippe_lm": 1.0, "detection_rate": det},
            {"envelope": "close", "n": 1, "survival_ippe_lm": 1.0, "detection_rate": det},
            {"envelope": "all", "n": n_all, "survival_ippe_lm": all_, "detection_rate": det}]


def test_pooled_row_weights_seeds_by_their_approaches(script):
    p = script("benchmarks/detector_protocol.py")
    text = p.pooled({1: _rows(100, 0.80, 300, 0.90), 2: _rows(300, 0.60, 100, 0.50, det=0.5)})
    # all: (0.90·300 + 0.50·100) / 400 = 80.0 %; far: (0.80·100 + 0.60·300) / 400 = 65.0 %; detection 87.5 %
    assert "400 approaches" in text and "survival 80.0 %" in text and "far 65.0 %" in text
    assert "detection 87.5 %" in text


def test_seed_sets_are_disjoint_and_fixed(script):
    p = script("benchmarks/detector_protocol.py")
    assert p.VALIDATION_SEED == p.VALIDATION_SEEDS[0] == 20_261_122
    assert not set(p.VALIDATION_SEEDS) & set(p.TEST_SEEDS)
    assert len(p.TEST_SEEDS) >= 3 and len(set(p.VALIDATION_SEEDS)) == len(p.VALIDATION_SEEDS) == 4


@pytest.mark.parametrize("bad", [[777_001], [5]])
def test_seeds_outside_the_split_are_refused(script, bad, monkeypatch, capsys):
    p = script("benchmarks/detector_protocol.py")
    monkeypatch.setattr("sys.argv", ["detector_protocol.py", "--split", "validation", "--seeds", *map(str, bad)])
    monkeypatch.setattr(p, "detector", lambda model, second=None, **w: None)
    with pytest.raises(SystemExit, match="not in the validation split"):
        p.main()


def test_second_names_a_pass_2_network_of_its_own(script):
    """``--second``: pass 1 is ``--model`` (default: the shipped weights), pass 2 the given network; without it
    both passes are one network."""
    from vbl_robust.detect.shipped import DEFAULT_MODEL
    from vbl_robust.detect.twostage import TwoStageDetector

    p = script("benchmarks/detector_protocol.py")
    one = p.detector(str(DEFAULT_MODEL), min_side=40.0)
    assert isinstance(one, TwoStageDetector) and one.second is one.first and one.min_side == 40.0
    two = p.detector(None, str(DEFAULT_MODEL))
    assert isinstance(two, TwoStageDetector) and two.second is not two.first and "second=" in repr(two)
    assert two.first.path == two.second.path == DEFAULT_MODEL


def test_compare_pairs_the_approaches_of_the_seeds_both_files_hold(script):
    p = script("benchmarks/detector_protocol.py")
    new = {"validation": {"1": [], "2": []}, "survived": {"1": [True, True, False], "2": [True, False]}}
    old = {"validation": {"1": []}, "survived": {"1": [False, True, False]}}
    text = p.compare(new, old)
    assert "| 1 | 3 | 1 | 1 | 0 | 1 | +1 | 1.0000 |" in text and "| pooled | 3 |" in text and "| 2 |" not in text
    with pytest.raises(SystemExit, match="no per-approach results"):
        p.compare(new, {"validation": {"1": []}})
    with pytest.raises(SystemExit, match="no validation seed in both"):
        p.compare(new, {"validation": {"9": []}, "survived": {"9": [True]}})
    with pytest.raises(SystemExit, match="not single with twostage"):  # a file without "design" is two-stage
        p.compare({**new, "design": "single"}, old)
    assert "| pooled | 3 |" in p.compare({**new, "design": "single"}, {**old, "design": "single"})


def test_design_single_is_the_network_alone_and_refuses_a_pass_2(script):
    """``--design single``: the network (``--model`` or the shipped one) on the 320-px view, no crop; a pass-2
    network or a crop window makes no sense there and is refused."""
    from vbl_robust.detect.shipped import DEFAULT_MODEL
    from vbl_robust.detect.twostage import TwoStageDetector

    p = script("benchmarks/detector_protocol.py")
    one = p.detector(str(DEFAULT_MODEL), design="single")
    assert not isinstance(one, TwoStageDetector) and one.path == DEFAULT_MODEL
    assert not isinstance(p.detector(None, design="single"), TwoStageDetector)
    with pytest.raises(SystemExit, match="no pass 2"):
        p.detector(None, str(DEFAULT_MODEL), design="single")
    with pytest.raises(SystemExit, match="no pass 2"):
        p.detector(str(DEFAULT_MODEL), design="single", min_side=40.0)
