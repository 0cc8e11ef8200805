"""Training step J of the default detector (MODEL_CARD.md, training log): v6 → a wider synthetic world.

What changes against step H (v6): 2000 airports instead of 200, runway lengths 1.5–4.5 km instead of
1.5–4.0 km, far approaches drawn twice as often as medium or close (the far envelope is where v6 misses its
gates on unseen airports, issue 14). Same schedule family as H. Resumable: rerun the same command after an
interruption (``resume=True`` continues ``last.pt``); one torch thread so that other work can run beside it.

    OMP_NUM_THREADS=1 python tools/train_step_j.py [--epochs 5]
"""

from __future__ import annotations

import argparse
import logging

import torch

from vbl_robust.detect.shipped import DEFAULT_MODEL
from vbl_robust.detect.train import train

#: generator options of the step-J data (train and the ultralytics validation split)
STEP_J_DATA = {"weights": (2.0, 1.0, 1.0), "runway_length_range_m": (1500.0, 4500.0)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="train_runs/step_j")
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--n-train", type=int, default=3000)
    args = ap.parse_args()
    torch.set_num_threads(1)
    logging.basicConfig(level=logging.INFO)
    res = train(args.out, n_train=args.n_train, n_val=60, epochs=args.epochs, imgsz=320, crops_per_sample=1,
                seed=7, batch=16, workers=0, resume=True, init_weights=DEFAULT_MODEL, n_airports=2000,
                generate_options=STEP_J_DATA, threads=1, optimizer="AdamW", lr0=0.0003, lrf=0.1,
                warmup_epochs=0.1, min_box=24, pose=36.0, save_period=1)
    print(f"stage {res.stage_dir}: last {res.last}")


if __name__ == "__main__":
    main()
