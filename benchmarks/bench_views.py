"""The black-box objective against its detector's bare forwards, per design and engine, and where its time goes.

For each installed engine (torch, ONNX Runtime, OpenVINO; fp32, one thread) and each design of the shipped model
(single pass; two-stage: a letterbox forward, then one on a crop): the objective's evaluations per second on θ of
roll ±15° × contrast [0.7, 1.4] (one generated 1024-px approach, batch 32) against the same detector's bare forwards
on 320-px views, one forward per evaluation for the single pass and two for the two-stage. Both sides in one
process, alternating, timed on the process clock (CPU seconds of this process: waiting for a core that other work
holds does not count), the fastest of several repetitions each (the least disturbed by what the process clock does
not exclude: shared caches and memory bandwidth). The ratio is the share of the objective's time spent in the
network: what sampling the views, NMS, selection and PnP cost on top. The objective also runs with the torch kernel
of the black-box views (``ViewSampler.opencv = False``: the views before issue 50) in the same rounds.

Then one two-stage objective call on ONNX Runtime under cProfile: its time by stage, and the functions with the
most time of their own. ``python benchmarks/bench_views.py [--quick]``.
"""

from __future__ import annotations

import cProfile
import pstats
import sys
import time

import numpy as np
import torch

BOX_RANGES = {"roll_deg": (-15.0, 15.0), "contrast": (0.7, 1.4)}


def _cpu_seconds(fn) -> float:
    """Seconds of this process's CPU time that ``fn()`` takes (work of other processes does not count)."""
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def _side_by_side(obj, det, theta: np.ndarray, forwards: int, reps: int) -> tuple[float, float, float]:
    """``(objective evaluations/s, the same with the torch view kernel, bare evaluations/s)``: the objective on
    ``theta`` (one batch) with the OpenCV and with the torch kernel of the black-box views
    (``ViewSampler.opencv``), and ``forwards`` bare forwards of the pose network on as many 320-px views, in turn,
    the fastest of ``reps`` each, in seconds of the process clock."""
    from vbl_robust.perturb.views import ViewSampler

    net = det.first if hasattr(det, "first") else det
    views = torch.rand(len(theta), 3, net.imgsz, net.imgsz, generator=torch.Generator().manual_seed(0))

    def bare() -> None:
        with torch.no_grad():
            for _ in range(forwards):
                net.raw_chunked(views)

    def with_kernel(opencv: bool) -> None:
        ViewSampler.opencv = opencv
        try:
            obj(theta)
        finally:
            ViewSampler.opencv = True

    obj(theta[:2])  # warm-up: pixels, model, caches
    bare()
    best = [float("inf")] * 3
    for _ in range(reps):
        for k, fn in enumerate((lambda: with_kernel(True), lambda: with_kernel(False), bare)):
            best[k] = min(best[k], _cpu_seconds(fn))
    return tuple(len(theta) / t for t in best)


#: stages of the profile: (label, the functions whose cumulative time is that stage's: (file suffix, name))
STAGES = (
    ("network forwards (engine)", (("detect/onnx.py", "raw"), ("detect/openvino.py", "raw"),
                                   ("detect/ultralytics.py", "raw"))),
    ("views (perturb/: sampling, photometry, statistics)", (("perturb/views.py", "views"),)),
    ("PnP", (("pnp/solvers.py", "solve"), ("pnp/__init__.py", "solve"))),
)


def _profile(obj, theta: np.ndarray, top: int) -> tuple[list[str], list[str]]:
    """Markdown rows: the objective's time by stage, and the ``top`` functions by own time."""
    obj(theta[:2])
    prof = cProfile.Profile()
    prof.enable()
    obj(theta)
    prof.disable()
    stats = pstats.Stats(prof).stats  # (file, line, name) -> (calls, primitive calls, own s, cumulative s, callers)
    total = sum(v[2] for v in stats.values())
    stage_rows, accounted = [], 0.0
    for label, funcs in STAGES:
        s = sum(v[3] for (f, _, name), v in stats.items() if any(f.endswith(sfx) and name == n for sfx, n in funcs))
        accounted += s
        stage_rows.append(f"| {label} | {s:.3f} | {s / total:.0%} |")
    stage_rows.append(f"| the rest (detector bookkeeping, NMS, selection, objective) | {total - accounted:.3f} | "
                      f"{(total - accounted) / total:.0%} |")
    stage_rows.append(f"| **one call, {len(theta)} θ** | **{total:.3f}** | 100% |")
    own = sorted(stats.items(), key=lambda kv: -kv[1][2])[:top]
    fn_rows = []
    for (f, line, name), (_, calls, tt, ct, _) in own:
        where = f.split("src/")[-1] if "src/" in f else f.rsplit("/", 1)[-1]
        fn_rows.append(f"| `{where}:{line}({name})` | {calls} | {tt:.3f} | {ct:.3f} |")
    return stage_rows, fn_rows


def main(quick: bool = False) -> str:
    from vbl_robust.detect.engines import installed_engines, with_engine
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.shipped import DEFAULT_MODEL, default_model_info, with_design
    from vbl_robust.detect.ultralytics import UltralyticsDetector
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.space import ParameterBox

    setup_offline()
    torch.set_num_threads(1)
    import cv2

    cv2.setNumThreads(1)
    reps, n = (3, 32) if quick else (12, 32)
    info = default_model_info()
    window = dict(info.get("twostage") or {})
    base = UltralyticsDetector(DEFAULT_MODEL, trust=True, imgsz=int(info.get("imgsz", 320)))
    sample = generate(1, seed=0)[0]
    box = ParameterBox(BOX_RANGES)
    theta = box.from_unit(np.random.default_rng(0).random((n, 2)))
    rows = ["| engine | design | bare forwards evals/s | objective evals/s | **objective / bare** | "
            "torch view kernel: evals/s | / bare |",
            "|---|---|---:|---:|---:|---:|---:|"]
    profiled = None
    for engine in installed_engines():
        det = with_engine(base, engine, trust=True)
        for design, forwards in (("single", 1), ("twostage", 2)):
            d = with_design(det, design, **(window if design == "twostage" else {}))
            obj = Objective(sample, d, box, batch_size=32)
            e_obj, e_torch, e_bare = _side_by_side(obj, d, theta, forwards, reps)
            rows.append(f"| {engine} | {design} | {e_bare:.1f} | {e_obj:.1f} | **{e_obj / e_bare:.2f}** | "
                        f"{e_torch:.1f} | {e_torch / e_bare:.2f} |")
            if engine == "onnxruntime" and design == "twostage":
                profiled = obj
    lines = [
        "## The black-box objective against its bare forwards",
        "",
        f"`python benchmarks/bench_views.py{' --quick' if quick else ''}`: the shipped model ({sample.width} × "
        f"{sample.height} generated approach, {n} θ of roll ±15° × contrast [0.7, 1.4] per call: one batch), one "
        f"torch / engine / OpenCV thread. Objective and bare forwards alternating in one process, on the process "
        f"clock, fastest of {reps} each; the two-stage's bare side is two forwards per evaluation. The last two "
        "columns sample the two-stage's views with the torch kernel (`ViewSampler.opencv = False`: the views before "
        "issue 50, still the differentiable and GPU path); the single pass renders whole frames with OpenCV either "
        "way. Goals (issue 50): two-stage ≥ 0.9 (moonshot 0.95), single pass ≥ 0.95.",
        "",
        *rows,
    ]
    if profiled is not None:
        stage_rows, fn_rows = _profile(profiled, box.from_unit(np.random.default_rng(1).random((2 * n, 2))), 12)
        lines += [
            "",
            f"Where one two-stage call on ONNX Runtime ({2 * n} θ, two batches) spends its time (cProfile; its overhead inflates the "
            "Python-heavy parts a little):",
            "",
            "| stage | s | share |",
            "|---|---:|---:|",
            *stage_rows,
            "",
            "| function (most time of its own) | calls | own s | cumulative s |",
            "|---|---:|---:|---:|",
            *fn_rows,
        ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
