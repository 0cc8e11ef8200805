"""A campaign with two worker processes, run as a script by tests/campaigns/test_orphans.py (``python
start_up_campaign.py OUT``). Its top level imports nothing heavy, as the ``vbl-robust`` command's does: each worker
(a spawned interpreter) imports this file as its main module before anything else."""

from __future__ import annotations

import sys


def main(out: str) -> None:
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
    from vbl_robust.store.core import ResultStore

    spec = CampaignSpec("start-up", (Block(boxes=(roll_box(5),), methods=("random",),
                                           budgets=(Budget(max_evals=8),)),), seed=5)
    with ResultStore(out) as store:
        summary = run_campaign(spec, generate(4, seed=3, width=96, height=96), store,
                               detector=DetectorSpec.oracle(0.5), workers=2)
    print(f"status={summary.status} done={summary.done}")


if __name__ == "__main__":
    main(sys.argv[1])
