"""Detectors and a campaign script for the runner tests (importable by name: DetectorSpec kind "factory").

Run as a script, it is the campaign the kill test interrupts: ``python campaign_helpers.py OUT N DELAY [term]``
(``term``: SIGTERM handled as the ``vbl-robust`` command handles it, :func:`vbl_robust.cli.common.stop_on_sigterm`);
``python campaign_helpers.py OUT N 0 workers-fail``: two worker processes whose detector cannot be built.
"""

from __future__ import annotations

import sys
import time

from vbl_robust.detect.oracle import OracleDetector


class BrokenDetector(OracleDetector):
    """Raises inside the pipeline: the sample's jobs must be recorded as failed, the campaign must go on."""

    def detect(self, context):
        raise RuntimeError("detector exploded")


class RefusedDetector(OracleDetector):
    """Refused while it is built (like an untrusted model file): the run fails before its first job."""

    def __init__(self, **kw):
        raise ValueError("refused model: pass --trust-model")


class FailsInWorkers(OracleDetector):
    """Built in the main process, refused in a worker process (like a model cache a worker cannot read)."""

    def __init__(self, **kw):
        import multiprocessing

        if multiprocessing.parent_process() is not None:
            raise RuntimeError("no model in this worker")
        super().__init__(**kw)


class SlowOracle(OracleDetector):
    """The oracle, sleeping ``delay`` seconds per batch (so a campaign is reliably killed mid-run)."""

    def __init__(self, delay: float = 0.05, **kw):
        super().__init__(**kw)
        self.delay = delay

    def detect(self, context):
        time.sleep(self.delay)
        return super().detect(context)


def kill_campaign_spec():
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box

    blk = Block(boxes=(roll_box(5), roll_box(10)), methods=("random", "georobust"), budgets=(Budget(max_evals=12),))
    return CampaignSpec("kill-test", (blk,), seed=5)


def main(out: str, n: int, delay: float, mode: str = "") -> None:
    import torch

    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.store.core import ResultStore

    torch.set_num_threads(1)
    samples = generate(n, seed=3, width=96, height=96)
    if mode == "workers-fail":
        det, workers = DetectorSpec("factory", "campaign_helpers:FailsInWorkers"), 2
    else:
        det, workers = DetectorSpec("factory", "campaign_helpers:SlowOracle", options={"delay": delay, "noise_px": 0.5}), 1
    with ResultStore(out) as store:
        summary = run_campaign(kill_campaign_spec(), samples, store, detector=det, workers=workers)
    print(f"status={summary.status} done={summary.done}")


if __name__ == "__main__":
    if sys.argv[4:] == ["term"]:
        from vbl_robust.cli.common import stop_on_sigterm

        stop_on_sigterm()
    main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), *sys.argv[4:5])
