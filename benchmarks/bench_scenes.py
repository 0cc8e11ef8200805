"""Scene-generation speed: rendered 1024 x 1024 images per second per envelope (1 OpenCV thread vs the default) and
the one-off cost of the first image in a fresh process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import cv2

# run in a fresh interpreter: import, procedural textures and the first 1024 x 1024 image
_COLD = """
import json, time
t0, c0 = time.perf_counter(), time.process_time()
import cv2
cv2.setNumThreads(1)
from vbl_robust.scenes import generate, textures
t1, c1 = time.perf_counter(), time.process_time()
generate(1, seed=0)[0].image
t2, c2 = time.perf_counter(), time.process_time()
for w in range(textures.N_WORLDS):
    textures.world_pyramid(w)
t3, c3 = time.perf_counter(), time.process_time()
print(json.dumps({"import": [t1 - t0, c1 - c0], "first": [t2 - t1, c2 - c1], "worlds": [t3 - t2, c3 - c2]}))
"""


def _load() -> str:
    return "{:.1f} / {:.1f} / {:.1f}".format(*os.getloadavg())


def _rate(samples) -> tuple[float, float]:
    """(images per wall-clock second, images per CPU second of this process)."""
    t0, c0 = time.perf_counter(), time.process_time()
    for s in samples:
        _ = s.image
        s.drop_pixels()
    return len(samples) / (time.perf_counter() - t0), len(samples) / (time.process_time() - c0)


def _cold() -> dict:
    out = subprocess.run([sys.executable, "-c", _COLD], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(quick: bool = False) -> str:
    from vbl_robust.scenes import textures
    from vbl_robust.scenes.generate import generate

    n = 6 if quick else 24
    default_threads = cv2.getNumThreads()
    cold, cold_load = _cold(), _load()
    for w in range(textures.N_WORLDS):  # one-off per process (measured above): procedural world rasters
        textures.world_pyramid(w)
    generate(2, seed=999)[0].image  # noqa: B018  (the remaining per-process caches)

    rows = []
    for env in ("close", "medium", "far", "all"):
        envs = ("close", "medium", "far") if env == "all" else (env,)
        rates = {}
        for threads in (1, default_threads):
            cv2.setNumThreads(threads)
            rates[threads] = _rate(generate(n, seed=123, envelopes=envs))
        rows.append((env, rates[1], rates[default_threads], _load()))
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
        f"| images per CPU-s ({default_threads} threads) | load avg 1/5/15 min |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for env, r1, rd, load in rows:
        lines.append(f"| {env} | {r1[0]:.1f} | {r1[1]:.1f} | {rd[0]:.1f} | {rd[1]:.1f} | {load} |")
    imp, first, worlds = cold["import"], cold["first"], cold["worlds"]
    lines += [
        "",
        "Images per CPU-second count only this process's CPU time: on a shared machine (see the load average, "
        "for a machine with " f"{os.cpu_count()} cores) wall-clock rates drop when other jobs compete for the cores, "
        "and CPU time itself grows with the contention for caches.",
        "",
        f"First image in a fresh process (load {cold_load}): importing `vbl_robust.scenes` {imp[0]:.2f} s "
        f"({imp[1]:.2f} CPU-s), then the first 1024 × 1024 image including its procedural world raster, detail "
        f"noise and sensor-noise buffer {first[0]:.2f} s ({first[1]:.2f} CPU-s); building the other "
        f"{textures.N_WORLDS - 1} world rasters (each is built on first use) {worlds[0]:.2f} s ({worlds[1]:.2f} "
        f"CPU-s). Pose sampling and labels alone (`generate` without touching pixels): {poses_per_s:.0f} samples/s.",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
