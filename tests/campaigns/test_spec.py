import re

import pytest

from vbl_robust.digest import canonical_json
from vbl_robust.paper.experiments import EXPERIMENTS, Options, experiment
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, derive_seed, roll_box, roll_contrast_box
from vbl_robust.specs.settings import PipelineSettings

SAMPLES = [("a", "fa"), ("b", "fb"), ("c", "fc")]


def spec(**kw):
    blk = Block(boxes=(roll_box(5), roll_box(15)), methods=("georobust", "random"), budgets=(Budget(max_evals=50),))
    return CampaignSpec("t", (blk,), **kw)


def test_expand_is_the_cross_product_with_unique_stable_keys():
    jobs = spec().expand(SAMPLES, detector_id="d")
    assert len(jobs) == 3 * 2 * 2
    keys = [j.key for j in jobs]
    assert len(set(keys)) == len(keys)
    assert keys == [j.key for j in spec().expand(SAMPLES, detector_id="d")]


def test_keys_change_with_what_changes_results():
    base = {j.key for j in spec().expand(SAMPLES, detector_id="d")}
    assert base.isdisjoint(j.key for j in spec().expand(SAMPLES, detector_id="other"))
    assert base.isdisjoint(j.key for j in spec(settings=PipelineSettings(eps_safe_m=500.0)).expand(SAMPLES, detector_id="d"))
    assert base.isdisjoint(j.key for j in spec().expand([("a", "changed")], detector_id="d"))
    # growing the dataset keeps the existing jobs' keys (and seeds): a rerun with more images resumes
    grown = {j.key for j in spec().expand([*SAMPLES, ("d", "fd")], detector_id="d")}
    assert base < grown


def test_seed_stream_depends_on_identity_not_order():
    fwd = {(j.sample_id, j.method, j.box.label): j.seed for j in spec(seed=1).expand(SAMPLES)}
    rev = {(j.sample_id, j.method, j.box.label): j.seed for j in spec(seed=1).expand(SAMPLES[::-1])}
    assert fwd == rev
    assert len(set(fwd.values())) == len(fwd)
    assert fwd != {k: j.seed for k, j in zip(fwd, spec(seed=2).expand(SAMPLES), strict=True)}
    assert derive_seed(0, "x") == derive_seed(0, "x") < 2**31


def test_canonical_json_treats_integral_floats_as_ints():
    assert canonical_json({"b": 15.0, "a": [1.5]}) == canonical_json({"a": [1.5], "b": 15})


def test_spec_round_trips_through_dict():
    for name, exp in EXPERIMENTS.items():
        s = exp.build(4, Options())
        again = CampaignSpec.from_dict(s.to_dict())
        assert again.to_dict() == s.to_dict(), name
        assert [j.key for j in again.expand(SAMPLES)] == [j.key for j in s.expand(SAMPLES)]


def test_block_and_budget_validation():
    with pytest.raises(ValueError, match="at least one of max_evals"):
        Budget()
    with pytest.raises(ValueError, match="max_evals"):
        Budget(max_evals=0)
    with pytest.raises(ValueError, match="role"):
        Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=5),), role="x")
    with pytest.raises(ValueError, match="sorted by level"):
        Block(boxes=(roll_box(15), roll_box(5)), methods=("random",), budgets=(Budget(max_evals=5),), chain=True)
    with pytest.raises(ValueError, match="unique"):
        spec().expand([("a", "1"), ("a", "2")])
    with pytest.raises(ValueError, match="unknown experiment 'nope'"):
        experiment("nope")


def test_experiment_defaults_follow_the_paper():
    s1 = experiment("spatial-1d").build(0, Options())
    main = s1.blocks[0]
    assert [b.level for b in main.boxes] == [2, 5, 10, 15, 20, 30]
    assert main.methods == ("georobust", "georobust-av", "random", "apgd")  # the paper's GeoRobust and ours
    assert main.budgets == (Budget(max_evals=200, stop_at_breach=True),)
    ref = s1.blocks[1]
    assert ref.role == "reference" and ref.options["grid"]["counts"] == [1201]  # 0.05° over ±30°
    s2 = experiment("spatial-2d").build(0, Options())
    assert s2.blocks[0].boxes[-1] == roll_contrast_box(30, (0.4, 2.5))
    conv = experiment("convergence").build(0, Options())
    assert conv.blocks[0].budgets[0].max_iters == 30 and conv.blocks[0].methods == ("georobust",)
    assert conv.blocks[0].budgets[0].max_evals == 3000  # a flat region would make PO_k explode
    rt = experiment("runtime-1d").build(0, Options())
    # anytime methods: one run at the largest budget, every budget read off its trace
    (once,) = rt.blocks[0].budgets
    assert rt.blocks[0].methods == ("georobust", "georobust-av", "random")
    assert once.max_seconds == 5.0 and once.min_evals == 200 and not once.stop_at_breach
    assert once.read_seconds == (0.1, 0.5, 1.0, 2.0, 5.0) and once.read_evals == (10, 25, 50, 100, 200)
    assert [b.label for b in once.read_budgets()] == [f"{t:g} s, no early stop" for t in once.read_seconds] + [
        f"{n} evals, no early stop" for n in once.read_evals]
    # APGD (its schedule depends on the budget): one run per budget, with the same budget labels
    assert rt.blocks[1].methods == rt.blocks[2].methods == ("apgd",)
    assert sorted(b.max_seconds for b in rt.blocks[1].budgets) == [0.1, 0.5, 1.0, 2.0, 5.0]
    assert [b.max_evals for b in rt.blocks[2].budgets] == [10, 25, 50, 100, 200]
    assert "read off" in rt.notes
    dp = experiment("distance-profile").build(0, Options())
    assert dp.blocks[0].chain and dp.blocks[0].boxes[-1].level == 45
    assert [e.images for e in EXPERIMENTS.values()].count(100) == 7 and EXPERIMENTS["pnp-validation"].images == 1000


def test_method_options_reach_only_their_method_and_change_its_keys():
    base = CampaignSpec("t", (
        Block(boxes=(roll_contrast_box(5, (0.8, 1.2)),), methods=("georobust-a", "random"),
              budgets=(Budget(max_evals=50),)),
        Block(boxes=(roll_contrast_box(5, (0.8, 1.2)),), methods=("grid",), budgets=(Budget(max_evals=9),),
              role="reference", options={"grid": {"counts": [3, 3]}}),
    ))
    tuned = base.with_method_options({"georobust-a": {"min_ratio": 9}, "grid": {"batch_size": 4}})
    jobs, old = tuned.expand(SAMPLES), {j.key: j for j in base.expand(SAMPLES)}
    by_method = {}
    for j in jobs:
        by_method.setdefault(j.method, []).append(j)
    assert all(j.options == {"min_ratio": 9} and j.key not in old for j in by_method["georobust-a"])
    assert all(j.options == {} and j.key in old for j in by_method["random"])
    # merged over the block's own options, not replacing them
    assert all(j.options == {"counts": [3, 3], "batch_size": 4} for j in by_method["grid"])
    assert CampaignSpec.from_dict(tuned.to_dict()).expand(SAMPLES) == jobs


@pytest.mark.parametrize("options, message", [
    ({"apgd": {"steps": 3}}, "no search runs method(s) ['apgd']"),
    ({"georobust-a": {"min_ratio": 0.5}}, "min_ratio must be a finite number >= 1"),
    ({"random": {"alpha": 2}}, "has no option(s) ['alpha']"),
])
def test_method_options_are_checked_before_anything_runs(options, message):
    base = CampaignSpec("t", (Block(boxes=(roll_box(5),), methods=("georobust-a", "random"),
                                    budgets=(Budget(max_evals=50),)),))
    with pytest.raises(ValueError, match=re.escape(message)):
        base.with_method_options(options)
