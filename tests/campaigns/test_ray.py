"""The Ray executor on a local Ray instance gives the same rows as the local executor for the same seed."""

import os
from pathlib import Path

import pytest

from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.store.core import ResultStore

HERE = Path(__file__).resolve().parent


@pytest.mark.slow
def test_ray_and_local_executors_agree(tmp_path, small_samples, oracle):
    import ray

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
                assert {r.provenance.executor for r in st.runs()} == {executor}
        finally:
            if executor == "ray":
                ray.shutdown()
    assert results["ray"] == results["local"]
    assert len(results["local"]) == 4


def test_an_address_that_accepts_tcp_but_is_not_ray_is_refused_within_the_timeout():
    """A port that accepts connections and never answers (not a Ray service) passed the TCP check and then hung
    in ray.init for minutes; the gRPC handshake refuses it within the timeout, while a real gRPC server passes."""
    import socket
    import time
    from concurrent.futures import ThreadPoolExecutor

    import grpc

    from vbl_robust.campaigns.runner import check_executor, grpc_answers

    silent = socket.create_server(("127.0.0.1", 0))
    try:
        port = silent.getsockname()[1]
        start = time.monotonic()
        with pytest.raises(ValueError, match=f"127.0.0.1:{port}.*completes no gRPC handshake"):
            check_executor("ray", f"127.0.0.1:{port}", timeout_s=1.0)
        assert time.monotonic() - start < 30
    finally:
        silent.close()
    server = grpc.server(ThreadPoolExecutor(1))
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        assert grpc_answers("127.0.0.1", port, 5.0)
        check_executor("ray", f"127.0.0.1:{port}", timeout_s=5.0)
        # a Ray Client address is refused before any connection: runs stream rows back, which Ray Client cannot carry
        with pytest.raises(ValueError, match=f"--address ray://127.0.0.1:{port}: Ray Client addresses are not"):
            check_executor("ray", f"ray://127.0.0.1:{port}", timeout_s=5.0)
    finally:
        server.stop(None)
