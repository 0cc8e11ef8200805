"""Scene-generation speed: rendered 1024 x 1024 images per second, per envelope, 1 OpenCV thread vs default."""

from __future__ import annotations

import sys
import time

import cv2


def _rate(samples) -> tuple[float, float]:
    """(images per wall-clock second, images per CPU second of this process)."""
    t0, c0 = time.perf_counter(), time.process_time()
    for s in samples:
        _ = s.image
        s.drop_pixels()
    return len(samples) / (time.perf_counter() - t0), len(samples) / (time.process_time() - c0)


def main(quick: bool = False) -> str:
    from vbl_robust.scenes import generate, textures

    n = 4 if quick else 24
    default_threads = cv2.getNumThreads()
    t0 = time.perf_counter()
    for w in range(textures.N_WORLDS):  # one-off per process: procedural world rasters
        textures.world_pyramid(w)
    textures.detail_pyramid()
    warmup_s = time.perf_counter() - t0
    generate(2, seed=999)[0].image  # noqa: B018  (first-call imports and caches)

    rows = []
    for env in ("close", "medium", "far", "all"):
        envs = ("close", "medium", "far") if env == "all" else (env,)
        rates = {}
        for threads in (1, default_threads):
            cv2.setNumThreads(threads)
            samples = generate(n, seed=123, envelopes=envs)
            rates[threads] = _rate(samples)
        rows.append((env, rates[1], rates[default_threads]))
    cv2.setNumThreads(default_threads)
    t0 = time.perf_counter()
    samples = generate(200 if not quick else 50, seed=5)
    poses_per_s = len(samples) / (time.perf_counter() - t0)

    lines = [
        "## Synthetic scenes: rendering speed",
        "",
        f"`python benchmarks/bench_scenes.py{' --quick' if quick else ''}` — 1024 × 1024 RGB, LARD V2 envelopes, "
        f"{n} images per cell, single process; `cv2.setNumThreads(1)` vs OpenCV's default ({default_threads}).",
        "",
        f"| envelope | images/s (1 thread) | images per CPU-s (1 thread) | images/s ({default_threads} threads) "
        "| ratio threads/1 |",
        "|---|---:|---:|---:|---:|",
    ]
    for env, r1, rd in rows:
        lines.append(f"| {env} | {r1[0]:.2f} | {r1[1]:.2f} | {rd[0]:.2f} | {rd[0] / r1[0]:.2f} |")
    lines += [
        "",
        "Images per CPU-second counts only this process's CPU time (the machine may be shared; wall-clock rates "
        "drop when other jobs compete for the cores).",
        "",
        f"One-off per process: building the {textures.N_WORLDS} procedural world rasters and the detail noise took "
        f"{warmup_s:.1f} s. Pose sampling and labels alone (`generate` without touching pixels): "
        f"{poses_per_s:.0f} samples/s.",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
