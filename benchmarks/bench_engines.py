"""Inference engines side by side on the shipped model: bare forward and end-to-end evaluations per second.

For each installed engine (torch, ONNX Runtime, OpenVINO — all fp32): the bare forward of the 320-px network
(images/s at batch 1, 8, 32, the views the single pass hands it) and the end-to-end objective (roll + contrast
→ detect → select → ippe_lm PnP) for the single pass and the two-stage design at batch 32, with the largest
keypoint difference to torch on those views (must stay ≤ 1e-3 px). Engines one after the other in one run, one torch /
engine thread; ratios to torch. ``python benchmarks/bench_engines.py [--quick]``.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch


def _rate(fn, n_items: int, reps: int) -> float:
    fn()  # warm-up
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    return n_items * reps / (time.perf_counter() - t)


def main(quick: bool = False) -> str:
    from vbl_robust.detect.base import DetectContext
    from vbl_robust.detect.engines import installed_engines, with_engine
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.shipped import DEFAULT_MODEL, with_design
    from vbl_robust.detect.ultralytics import UltralyticsDetector
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.space import ParameterBox

    setup_offline()
    torch.set_num_threads(1)
    reps = 2 if quick else 6
    base = UltralyticsDetector(DEFAULT_MODEL, trust=True, imgsz=320)
    engines = {e: with_engine(base, e, trust=True) for e in installed_engines()}
    sample = generate(1, seed=4)[0]
    box = ParameterBox({"roll_deg": (-10, 10), "contrast": (0.7, 1.3)})
    theta = box.from_unit(np.random.default_rng(0).random((32, 2)))
    views = torch.rand(32, 3, 320, 320)
    ref = base.top(DetectContext.of_images(views)).keypoints
    lines = ["| engine | bare images/s b1 / b8 / b32 | × torch (b32) | single e2e evals/s (b32) | two-stage e2e "
             "evals/s (b32) | max keypoint diff to torch (px) |", "|---|---|---|---|---|---|"]
    rows = {}
    for name, det in engines.items():
        bare = []
        for b in (1, 8, 32):
            v = views[:b]
            with torch.no_grad():
                bare.append(_rate(lambda v=v, det=det: det.raw(v), b, reps))
        with torch.no_grad():
            diff = float((det.top(DetectContext.of_images(views)).keypoints - ref).abs().max())
        single = Objective(sample, with_design(det, "single"), box, batch_size=32)
        two = Objective(sample, with_design(det, "twostage"), box, batch_size=32)
        rows[name] = (bare, _rate(lambda o=single: o(theta), 32, reps), _rate(lambda o=two: o(theta), 32, reps), diff)
    t32 = rows["torch"][0][2]
    for name, (bare, e_single, e_two, diff) in rows.items():
        lines.append(f"| {name} | {' / '.join(f'{r:.1f}' for r in bare)} | {bare[2] / t32:.2f} | {e_single:.1f} | "
                     f"{e_two:.1f} | {diff:.1e} |")
    return "\n".join([
        "## Inference engines (fp32) on the shipped model",
        "",
        "`python benchmarks/bench_engines.py`: bare forward of the 320-px network and the end-to-end objective per "
        f"engine, one thread, {reps} repetitions per engine, one engine after the other (contention from other jobs weighs on each in turn); two-stage = two forwards per evaluation. "
        "The keypoint difference is on random 320-px views (the budget is 1e-3 px).",
        "",
        *lines,
        "",
    ])


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
