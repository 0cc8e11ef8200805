"""The Ray executor on a local Ray instance gives the same rows as the local executor for the same seed."""

import os
from pathlib import Path

import pytest

from vbl_robust.campaigns import Block, Budget, CampaignSpec, ResultStore, roll_box, run_campaign

HERE = Path(__file__).resolve().parent


@pytest.mark.slow
def test_ray_and_local_executors_agree(tmp_path, small_samples, oracle):
    ray = pytest.importorskip("ray")
    blk = Block(boxes=(roll_box(10),), methods=("georobust", "random"), budgets=(Budget(max_evals=10),))
    spec = CampaignSpec("ray-test", (blk,), seed=2)
    samples = small_samples[:2]
    results = {}
    for executor in ("local", "ray"):
        if executor == "ray":
            # workers import vbl_robust from the installed package; no dashboard, 2 CPUs as on this machine
            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": {"OMP_NUM_THREADS": "1", "PYTHONPATH": os.environ.get("PYTHONPATH", "")}})
        try:
            with ResultStore(tmp_path / executor / "r.sqlite") as st:
                summary = run_campaign(spec, samples, st, detector=oracle, executor=executor)
                results[executor] = {r.key: (r.worst_m, r.nfev, r.worst_x, r.verdict)
                                     for r in st.jobs(with_trace=False)}
                assert summary.status == "finished" and summary.done == 4
                assert {r["executor"] for r in st.runs()} == {executor}
        finally:
            if executor == "ray":
                ray.shutdown()
    assert results["ray"] == results["local"]
    assert len(results["local"]) == 4
