"""The oracle pipeline: L(θ) with a perfect detector over roll ±30° × contrast [0.4, 2.5], per PnP solver.

Camera roll about the optical axis does not move the camera, so with exact corners (``OracleDetector()``) every
L(θ) should be ~0; any row with L ≥ 1 m is a *solver* failure. With fixed 0.5 px corner noise per sample
(``OracleDetector(noise_px=0.5)``, a systematic detector error that does not rotate with the image) L becomes
roll-dependent and the solvers' robustness to noise shows. Samples: ``vbl_robust.scenes.generate`` (LARD V2
envelopes, 1024 × 1024, 60°). Also the objective's evaluation rate with the oracle (pixels are not perturbed
for it) on both paths.

Run: ``python benchmarks/bench_pipeline.py`` (or ``--quick``).
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from vbl_robust.detect.oracle import OracleDetector
from vbl_robust.pipeline import Objective
from vbl_robust.scenes.generate import generate
from vbl_robust.space import ParameterBox

BOX = ParameterBox({"roll_deg": (-30, 30), "contrast": (0.4, 2.5)})
SOLVERS = ("ippe_lm", "iterative", "sqpnp")


def _grid(n_roll: int) -> np.ndarray:
    r, c = np.meshgrid(np.linspace(-30.0, 30.0, n_roll), (0.4, 1.0, 2.5), indexing="ij")
    return np.stack([r.ravel(), c.ravel()], axis=1)


def main(quick: bool = False) -> str:
    torch.set_num_threads(1)
    n_samples, n_roll = (12, 7) if quick else (120, 13)
    samples = generate(n_samples, seed=123)
    theta = _grid(n_roll)
    lines = [
        "## Oracle pipeline: roll invariance per PnP solver",
        "",
        f"`python benchmarks/bench_pipeline.py{' --quick' if quick else ''}` — {n_samples} generated approaches "
        f"(seed 123) × {len(theta)} θ (roll {n_roll} values in ±30°, contrast 0.4 / 1 / 2.5) = "
        f"{n_samples * len(theta)} evaluations per row.",
        "",
        "| detector | PnP | rows with L ≥ 1 m | rows with L ≥ 1000 m (ε_safe) | failures (5000 m) | median L (m) | "
        "95th pct L (m) | max L (m) |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for label, make in (("oracle, exact", OracleDetector), ("oracle, 0.5 px fixed noise", lambda: OracleDetector(noise_px=0.5))):
        for pnp in SOLVERS:
            loss, failed = [], 0
            for s in samples:
                rec = Objective(s, make(), BOX, pnp=pnp).evaluate(theta)
                loss.append(rec.loss)
                failed += int(rec.failed.sum())
            L = np.concatenate(loss)
            lines.append(
                f"| {label} | {pnp} | {np.mean(L >= 1.0):.1%} ({int(np.sum(L >= 1.0))}) | "
                f"{np.mean(L >= 1000.0):.1%} ({int(np.sum(L >= 1000.0))}) | {failed} | "
                f"{np.median(L):.3g} | {np.percentile(L, 95):.3g} | {L.max():.3g} |"
            )

    obj = Objective(samples[0], OracleDetector(noise_px=0.5), BOX)
    obj(theta[:2])
    obj(torch.tensor(theta[:2], requires_grad=True)).values.sum().backward()  # warm-up
    big = np.tile(theta, (3, 1))
    t0 = time.perf_counter()
    obj(big)
    t_np = time.perf_counter() - t0
    t = torch.tensor(big, requires_grad=True)
    t0 = time.perf_counter()
    obj(t).values.sum().backward()
    t_torch = time.perf_counter() - t0
    lines += [
        "",
        f"Oracle objective rate ({len(big)} θ in one call, 1 torch thread): black-box path "
        f"{len(big) / t_np:.0f} evaluations/s, differentiable path (forward + backward) {len(big) / t_torch:.0f} "
        "evaluations/s.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
