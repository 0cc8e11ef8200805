"""Hardening (campaigns/harden.py): worst-of-k training views — the audit's perturbation with exact labels, the audit's
loss, the audit's random search — and its rounds, typed both ways."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vbl_robust.campaigns.harden import (
    NOT_TRAINABLE,
    Round,
    candidate_seed,
    perturbed_sample,
    trainable,
    worst_of_k,
)
from vbl_robust.detect.base import Detections
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.perturb.compose import Perturbation
from vbl_robust.pnp.solvers import solve
from vbl_robust.space import ParameterBox


@pytest.fixture(scope="module")
def sample():
    from vbl_robust.scenes.generate import generate

    return generate(1, seed=3, width=256, height=256)[0]


class RollGate(OracleDetector):
    """The oracle, but nothing detected where roll > 4°: L is the 5000 m penalty exactly there."""

    def detect(self, context):
        dets = super().detect(context)
        roll = np.asarray(context.theta, dtype=np.float64)[:, 0]
        return [Detections.empty() if r > 4.0 else d for d, r in zip(dets, roll, strict=True)]


@pytest.mark.parametrize("theta", [[6.0, 0.0, 0.0], [-3.0, 1.5, -2.0]])
def test_a_perturbed_sample_is_the_perturbation_with_exact_labels(sample, theta):
    p = Perturbation(["roll_deg", "pitch_deg", "yaw_deg"])
    th = np.array([theta])
    out = perturbed_sample(sample, p, th[0], tag="t")
    expected = p.images_numpy(sample.image, th, K=sample.K)[0]
    assert out.image.dtype == np.uint8 and np.abs(out.image / 255.0 - expected).max() <= 0.5 / 255 + 1e-6
    np.testing.assert_allclose(out.corners_2d, p.points(sample.corners_2d, th, K=sample.K)[0])
    # a rotation about the optical centre: PnP on the moved corners finds the same camera position
    pos = solve(out.corners_2d[None], out.corners_3d, out.K, method="ippe_lm").position[0]
    assert np.linalg.norm(pos - sample.position) < 1e-6 * np.linalg.norm(sample.position)
    assert out.id == f"{sample.id}#t" and out.R is None and out.meta["perturbation"]["roll_deg"] == theta[0]


def test_a_corner_out_of_the_image_is_not_trainable(sample):
    p = Perturbation(["yaw_deg"])
    far = np.array([[40.0]])  # the runway leaves a 60° field of view
    assert not trainable(sample, p, far)[0] and trainable(sample, p, np.array([[0.0]]))[0]
    with pytest.raises(ValueError, match="out of the image"):
        perturbed_sample(sample, p, far[0])


def test_worst_of_k_finds_the_failure_region_with_the_audit_loss(sample):
    box = ParameterBox({"roll_deg": (-10.0, 10.0)})
    w = worst_of_k(sample, RollGate(), box, 16, 0)
    assert w.theta[0] > 4.0 and w.value == 5000.0 and w.trainable == 16
    assert w.reason == "no_detection" and w.evaluations == 16 and w.failures["no_detection"] >= 1
    again = worst_of_k(sample, RollGate(), box, 16, 0)
    assert np.array_equal(again.theta, w.theta)  # seeded
    # the draws are the first hardening code's (default_rng(seed).random((k, d)) onto the box): the first breach wins
    drawn = box.from_unit(np.random.default_rng(0).random((16, 1)))
    assert np.array_equal(w.theta, drawn[np.argmax(drawn[:, 0] > 4.0)])
    # the previous worst joins the candidates: with one fresh draw in the safe half it still wins
    safe = ParameterBox({"roll_deg": (-10.0, 0.0)})
    kept = worst_of_k(sample, RollGate(), safe, 1, 1, previous=[w.theta])
    assert np.array_equal(kept.theta, w.theta) and kept.trainable == 2 and kept.evaluations == 2
    with pytest.raises(ValueError, match="k must be"):
        worst_of_k(sample, RollGate(), box, 0, 0)


def test_an_untrainable_candidate_is_a_failed_evaluation_never_the_worst(sample):
    """The search's bookkeeping: every candidate counted, the untrainable ones with their own reason."""
    box = ParameterBox({"yaw_deg": (-60.0, 60.0)})
    w = worst_of_k(sample, RollGate(), box, 12, 3)
    thetas = box.from_unit(np.random.default_rng(3).random((12, 1)))
    ok = trainable(sample, Perturbation(box), thetas)
    assert 0 < ok.sum() < 12 and w.trainable == ok.sum() and w.evaluations == 12
    assert w.failures[NOT_TRAINABLE] == 12 - ok.sum() and trainable(sample, Perturbation(box), w.theta[None])[0]
    far = ParameterBox({"yaw_deg": (50.0, 60.0)})  # every candidate turns the runway out of the frame
    none = worst_of_k(sample, RollGate(), far, 4, 0)
    assert none.theta is None and np.isnan(none.value) and none.trainable == 0 and none.reason is None
    assert none.failures == {NOT_TRAINABLE: 4}


@pytest.mark.parametrize("parts", [(0, 0, 0), (20_261_205, 1, 299), (2**40 + 3, 0, 5), (2**63 - 1, 99, 99_999)])
def test_the_candidate_seed_draws_what_the_first_hardening_code_drew(parts):
    a = np.random.default_rng(candidate_seed(*parts)).random((8, 2))
    np.testing.assert_array_equal(a, np.random.default_rng(list(parts)).random((8, 2)))


def test_a_round_is_read_back_as_it_was_written(tmp_path):
    rnd = Round(1, tmp_path, tmp_path / "w.pt", ((1.5, -2.0), None), (4321.0, float("nan")), 1, 2.5, 30.0,
                ("no_detection", None), 18, {"no_detection": 3, NOT_TRAINABLE: 2}, {"kind": "default", "sha256": "x"})
    rnd.write()
    back = Round.read(tmp_path)
    assert back.to_dict().keys() == rnd.to_dict().keys() and back.worst == rnd.worst and back.reasons == rnd.reasons
    assert (back.index, back.directory, back.weights, back.breaches, back.evaluations, back.failures, back.detector) == (
        1, tmp_path, tmp_path / "w.pt", 1, 18, rnd.failures, rnd.detector)
    assert back.values[0] == 4321.0 and np.isnan(back.values[1])
    # a round recorded before the search's bookkeeping reads back too
    old = {"index": 0, "weights": "w.pt", "worst": [[3.0]], "values": [12.0], "breaches": 0, "search_s": None,
           "train_s": None}
    assert Round.from_dict(old, tmp_path) == Round(0, tmp_path, Path("w.pt"), ((3.0,),), (12.0,), 0)


def test_harden_trains_on_the_worst_views_and_resumes(tmp_path, sample):
    """Two tiny rounds on the shipped model (64 px views, one epoch): each round records its worst θ per image and
    its weights; the second starts from the first's; a rerun reads the finished rounds back (no training)."""
    import json

    import torch

    from vbl_robust.campaigns.harden import harden
    from vbl_robust.scenes.generate import generate

    torch.set_num_threads(1)
    tr, va = generate(4, seed=11, width=256, height=256), generate(2, seed=12, width=256, height=256)
    box = ParameterBox({"roll_deg": (-20.0, 20.0), "contrast": (0.5, 2.0)})
    kw = dict(train_samples=tr, val_samples=va, rounds=2, k=3, epochs=1, imgsz=64, batch=4, workers=0, seed=0)
    rounds = harden(tmp_path / "h", box, **kw)
    assert [r.index for r in rounds] == [0, 1] and all(r.weights.exists() for r in rounds)
    first = json.loads((tmp_path / "h/round00/round.json").read_text())
    assert len(first["worst"]) == 4 and all(w is None or len(w) == 2 for w in first["worst"])
    assert any(w is not None for w in first["worst"]) and first["breaches"] == sum(v > 1000 for v in first["values"])
    assert first["search_s"] > 0 and first["train_s"] > 0  # recorded: the training time goes into the model card
    # the search's bookkeeping and the detector's identity, read back typed
    r0 = Round.read(tmp_path / "h/round00")
    assert r0.evaluations == 4 * 3 and len(r0.reasons) == 4 and r0.detector["kind"] == "default"
    r1 = Round.read(tmp_path / "h/round01")
    assert r1.evaluations == 4 * 3 + sum(w is not None for w in first["worst"])  # the previous worst join
    assert r1.detector["kind"] == "ultralytics" and r1.detector["path"] == str(rounds[0].weights)
    assert r1.detector["options"]["design"] == "twostage" and r1.detector["options"]["imgsz"] == 64
    import yaml

    args = yaml.safe_load((tmp_path / "h/round01/stage00/args.yaml").read_text())
    assert args["model"] == str(rounds[0].weights)  # round 1 fine-tunes round 0's weights
    # with the shipped model's recipe (detect.train.FINE_TUNE), not ultralytics' defaults
    assert (args["optimizer"], args["lr0"], args["lrf"], args["cos_lr"], args["pose"]) == ("AdamW", 1e-4, 0.1, True, 36.0)
    stamp = rounds[1].weights.stat().st_mtime_ns
    again = harden(tmp_path / "h", box, **kw)
    assert [r.weights for r in again] == [r.weights for r in rounds] and again[1].weights.stat().st_mtime_ns == stamp
    with pytest.raises(ValueError, match="lower bound of 'contrast'"):
        harden(tmp_path / "bad", ParameterBox({"contrast": (-1.0, 2.0)}), **kw)
    # resuming a later round loads a recorded round's weights (a pickle): only with the caller's trust, and only
    # weights inside the run's directory (issue 48 item 3)
    import shutil

    shutil.rmtree(tmp_path / "h" / "round01")
    with pytest.raises(ValueError, match="pass --trust-model if you trust the rounds"):
        harden(tmp_path / "h", box, **kw)
    record = tmp_path / "h" / "round00" / "round.json"
    crafted = json.loads(record.read_text())
    crafted["weights"] = str(tmp_path / "elsewhere.pt")
    record.write_text(json.dumps(crafted))
    with pytest.raises(ValueError, match="lie outside"):
        harden(tmp_path / "h", box, trust_rounds=True, **kw)


def test_the_command_refuses_bad_input_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from vbl_robust.cli import app

    pt = tmp_path / "m.pt"
    pt.write_bytes(b"x")
    runner = CliRunner()
    for args, message in ((["--perturb", "foo"], "unknown perturbation 'foo'"),
                          (["--perturb", "contrast=-1,2"], "contrast must lie within"),
                          (["--perturb", "roll_deg", "--model", str(tmp_path / "none.pt")], "file not found"),
                          (["--perturb", "roll_deg", "--model", str(pt)], "pass --trust-model"),
                          (["--perturb", "roll_deg", "--seed", "0"], "--seed 0: the approaches of this seed are an "
                                                                      "audit's"),
                          (["--perturb", "roll_deg", "--seed", "777001"], "never trained on"),
                          (["--perturb", "roll_deg", "--data", "lard"], "--data lard: choose audit or shipped"),
                          (["--perturb", "roll_deg", "--n-train", "2", "--n-val", "1", "--engine", "foo"],
                           "--engine foo: engine must be")):
        res = runner.invoke(app, ["harden", "--out", str(tmp_path / "h"), *args])
        assert res.exit_code == 2 and message in res.output, (args, res.output)
    assert not (tmp_path / "h").exists()


@pytest.mark.parametrize("data", ["audit", "shipped"])
def test_the_command_draws_its_approaches_from_the_data_it_names(tmp_path, monkeypatch, data):
    """``--data shipped``: the shipped model's own training mix (detect.train.SHIPPED_DATA), ``audit``: the
    generator's defaults; the validation approaches from the same mix."""
    from typer.testing import CliRunner

    from vbl_robust.campaigns import harden as harden_module
    from vbl_robust.cli import app
    from vbl_robust.detect.protocol import HARDEN_SEED
    from vbl_robust.detect.train import SHIPPED_DATA, VAL_SEED_OFFSET
    from vbl_robust.scenes.generate import generate

    seen = {}
    monkeypatch.setattr(harden_module, "harden", lambda out, box, **kw: seen.update(kw) or [])
    res = CliRunner().invoke(app, ["harden", "--perturb", "roll_deg", "--n-train", "6", "--n-val", "3", "--data", data,
                                   "--out", str(tmp_path / "h")])
    assert res.exit_code == 0, res.output
    assert (seen["engine"], seen["device"]) == ("torch", "cpu")  # the search's detector, as before the options
    options = SHIPPED_DATA if data == "shipped" else {}
    for key, n, seed in (("train_samples", 6, HARDEN_SEED), ("val_samples", 3, HARDEN_SEED + VAL_SEED_OFFSET)):
        want = [s.position.tolist() for s in generate(n, seed=seed, **options)]
        other = [s.position.tolist() for s in generate(n, seed=seed, **({} if options else SHIPPED_DATA))]
        got = [s.position.tolist() for s in seen[key]]
        assert got == want and got != other
