"""Worst-of-k training views (detect/harden.py): the audit's perturbation with exact labels, the audit's loss."""

from __future__ import annotations

import numpy as np
import pytest

from vbl_robust.detect.base import Detections
from vbl_robust.detect.harden import perturbed_sample, trainable, worst_of_k
from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.perturb import Perturbation
from vbl_robust.pnp import solve
from vbl_robust.space import ParameterBox


@pytest.fixture(scope="module")
def sample():
    from vbl_robust.scenes import generate

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
    w = worst_of_k(sample, RollGate(), box, 16, np.random.default_rng(0))
    assert w.theta[0] > 4.0 and w.value == 5000.0 and w.trainable == 16
    again = worst_of_k(sample, RollGate(), box, 16, np.random.default_rng(0))
    assert np.array_equal(again.theta, w.theta)  # seeded
    # the previous worst joins the candidates: with one fresh draw in the safe half it still wins
    safe = ParameterBox({"roll_deg": (-10.0, 0.0)})
    kept = worst_of_k(sample, RollGate(), safe, 1, np.random.default_rng(1), previous=[w.theta])
    assert np.array_equal(kept.theta, w.theta) and kept.trainable == 2
    with pytest.raises(ValueError, match="k must be"):
        worst_of_k(sample, RollGate(), box, 0, np.random.default_rng(0))


def test_harden_trains_on_the_worst_views_and_resumes(tmp_path, sample):
    """Two tiny rounds on the shipped model (64 px views, one epoch): each round records its worst θ per image and
    its weights; the second starts from the first's; a rerun reads the finished rounds back (no training)."""
    import json

    import torch

    from vbl_robust.detect.harden import harden
    from vbl_robust.scenes import generate

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
                          (["--perturb", "roll_deg", "--data", "lard"], "--data lard: choose audit or shipped")):
        res = runner.invoke(app, ["harden", "--out", str(tmp_path / "h"), *args])
        assert res.exit_code == 2 and message in res.output, (args, res.output)
    assert not (tmp_path / "h").exists()


@pytest.mark.parametrize("data", ["audit", "shipped"])
def test_the_command_draws_its_approaches_from_the_data_it_names(tmp_path, monkeypatch, data):
    """``--data shipped``: the shipped model's own training mix (detect.train.SHIPPED_DATA), ``audit``: the
    generator's defaults; the validation approaches from the same mix."""
    from typer.testing import CliRunner

    from vbl_robust.cli import app
    from vbl_robust.detect import harden as harden_module
    from vbl_robust.detect.protocol import HARDEN_SEED
    from vbl_robust.detect.train import SHIPPED_DATA, VAL_SEED_OFFSET
    from vbl_robust.scenes import generate

    seen = {}
    monkeypatch.setattr(harden_module, "harden", lambda out, box, **kw: seen.update(kw) or [])
    res = CliRunner().invoke(app, ["harden", "--perturb", "roll_deg", "--n-train", "6", "--n-val", "3", "--data", data,
                                   "--out", str(tmp_path / "h")])
    assert res.exit_code == 0, res.output
    options = SHIPPED_DATA if data == "shipped" else {}
    for key, n, seed in (("train_samples", 6, HARDEN_SEED), ("val_samples", 3, HARDEN_SEED + VAL_SEED_OFFSET)):
        want = [s.position.tolist() for s in generate(n, seed=seed, **options)]
        other = [s.position.tolist() for s in generate(n, seed=seed, **({} if options else SHIPPED_DATA))]
        got = [s.position.tolist() for s in seen[key]]
        assert got == want and got != other
