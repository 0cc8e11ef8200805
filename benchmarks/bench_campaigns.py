"""Campaign costs: per-job overhead of the runner + store vs a bare search, and how long each full experiment
takes here on the shipped detector (extrapolated from a partial run on a few images).

Usage::

    python benchmarks/bench_campaigns.py [--quick] [--oracle] [--images N]

The overhead is measured with the oracle detector (ground-truth corners, no network), which isolates the
runner's own cost; the durations use the shipped model (``--model default``, the two-stage design) — what a user
runs — unless ``--oracle``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path


def _detectors(oracle_only: bool):
    from vbl_robust.campaigns import DetectorSpec

    oracle = DetectorSpec.oracle()
    return oracle, (oracle if oracle_only else DetectorSpec("default"))


def _shipped_version() -> str:
    """``"v6, "`` from the shipped model's ``default.json`` (empty if it has no version)."""
    from vbl_robust.campaigns.provenance import default_model_info

    info = default_model_info()
    return f"v{info['version']}, " if "version" in info else ""


def overhead(detector, n_images: int, max_evals: int) -> tuple[str, list[dict]]:
    """Same jobs twice: bare ``maximize`` on a prebuilt objective, and through ``run_campaign`` into a store."""
    import numpy as np

    from vbl_robust.campaigns import Block, Budget, CampaignSpec, ResultStore, roll_box, run_campaign
    from vbl_robust.campaigns.work import detector_for
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes import generate
    from vbl_robust.search import maximize

    samples = generate(n_images, seed=11)
    methods = ("georobust", "random")
    box = roll_box(15)
    spec = CampaignSpec("bench", (Block(boxes=(box,), methods=methods, budgets=(Budget(max_evals=max_evals, stop_at_breach=False),)),))
    det = detector_for(detector)
    # warm-up (model, caches) outside the timings
    Objective(samples[0], det, box.box)(np.zeros((2, 1)))
    bare = []
    for s in samples:
        _ = s.image
        obj = Objective(s, det, box.box)
        for m in methods:
            t0 = time.perf_counter()
            r = maximize(obj, box.box, m, max_evals=max_evals, seed=0)
            bare.append((time.perf_counter() - t0, r.nfev))
    for s in samples:
        _ = s.image
    with tempfile.TemporaryDirectory() as d, ResultStore(Path(d) / "r.sqlite") as st:
        t0 = time.perf_counter()
        summ = run_campaign(spec, samples, st, detector=detector)
        camp = time.perf_counter() - t0
        rows = st.jobs(with_trace=False)
        size = (Path(d) / "r.sqlite").stat().st_size + sum(p.stat().st_size for p in Path(d).glob("r.sqlite-*"))
    t_bare = sum(t for t, _ in bare)
    nfev = sum(n for _, n in bare)
    per_eval = t_bare / nfev
    jobs = summ.done
    over = (camp - t_bare) / jobs
    search_s = sum(r.search_s for r in rows)
    text = (
        f"{jobs} jobs ({n_images} images × {', '.join(methods)}, roll ±15°, {max_evals} evaluations each, no early stop):\n\n"
        "| | seconds | per job | per evaluation |\n|---|---:|---:|---:|\n"
        f"| bare `maximize` on a prebuilt objective | {t_bare:.2f} | {t_bare / jobs:.3f} | {1000 * per_eval:.1f} ms |\n"
        f"| `run_campaign` (objective build, search, worst-point check, commit) | {camp:.2f} | {camp / jobs:.3f} | "
        f"{1000 * camp / nfev:.1f} ms |\n"
        f"| of which inside the searches | {search_s:.2f} | {search_s / jobs:.3f} | |\n\n"
        f"Overhead of the runner and store: **{over * 1000:.0f} ms per job** ({100 * (camp / t_bare - 1):.1f} % of the "
        f"bare search time; ≈ {over / per_eval:.1f} evaluations' worth: building the objective per sample, the re-evaluation "
        f"of the worst point, JSON encoding and one SQLite transaction). Store size: {size / jobs / 1024:.1f} KiB per job "
        "(trace + every evaluated point).\n"
    )
    return text, [{"per_eval_s": per_eval}]


def experiments(detector, n_images: int, quick: bool) -> str:
    """Run each experiment on ``n_images`` images and extrapolate to its default size."""
    from vbl_robust.campaigns import EXPERIMENTS, Options, ResultStore, load_samples, run_campaign

    opts = Options(max_evals=20, grid_step_deg=0.5, landscape=(11, 6), time_budgets=(0.1, 0.5), eval_budgets=(10, 20),
                   iterations=10) if quick else Options()
    lines = ["| experiment | images run | seconds | start-up (s) | per image (s) | fixed (landscape, s) | default images | "
             "estimated full run | evaluations per image |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, exp in EXPERIMENTS.items():
        k = n_images * (5 if name == "pnp-validation" else 1)  # a PnP job is one detector pass
        samples, source = load_samples(k, 0)
        with tempfile.TemporaryDirectory() as d, ResultStore(Path(d) / "r.sqlite") as st:
            t0 = time.perf_counter()
            run_campaign(exp.build(0, opts), samples, st, detector=detector, dataset_source=source)
            took = time.perf_counter() - t0
            rows = st.jobs(with_trace=False)
        fixed = sum(r.job_s or 0.0 for r in rows if r.role == "landscape")
        per_image = sum(r.job_s or 0.0 for r in rows if r.role != "landscape") / k
        start = max(0.0, took - fixed - per_image * k)  # model loading, store, scheduling: once per run
        evals = sum(r.nfev or 0 for r in rows if r.role != "landscape") / k
        full = start + fixed + per_image * exp.images
        lines.append(f"| {name} | {k} | {took:.0f} | {start:.0f} | {per_image:.1f} | {fixed:.0f} | {exp.images} | "
                     f"{full / 3600:.1f} h ({full / 60:.0f} min) | {evals:.0f} |")
    return "\n".join(lines) + "\n"


def main(quick: bool = False, oracle_only: bool = False, images: int | None = None) -> str:
    import torch

    torch.set_num_threads(1)
    oracle, det = _detectors(oracle_only)
    cmd = ("python benchmarks/bench_campaigns.py" + (" --quick" if quick else "") + (" --oracle" if oracle_only else "")
           + (f" --images {images}" if images else ""))
    t_over, _ = overhead(oracle, 1 if quick else 3, 20 if quick else 60)
    n = images or (1 if quick else 2)
    t_exp = experiments(det, n, quick)
    who = f"the shipped model ({_shipped_version()}two-stage, `--model default`)" if det.kind == "default" else \
        "the oracle detector"
    return (
        "## Campaigns: runner overhead and experiment durations\n\n"
        f"Command: `{cmd}`. Synthetic 1024 × 1024 approaches; 1 torch thread.\n\n"
        "### Per-job overhead of the runner and results store\n\n"
        "Oracle detector (ground-truth corners, no network), so that the runner's own cost is not hidden behind "
        "the network's.\n\n" + t_over +
        "\n### Duration of each experiment (default options"
        + (", *quick: reduced budgets*" if quick else "") + f"), detector: {who}\n\n"
        f"Each experiment was run on the first {n} images of the default sample stream ({5 * n} for pnp-validation) "
        "and extrapolated: start-up (model loading, store; the wall time not inside any job) once, the 2-D "
        "landscape grid (one image only) once, the per-image job time × the default number of images. Searches "
        "that breach stop early in the spatial experiments, so their durations depend on how robust the model is "
        "on the images drawn; the time-budget experiments cost at least "
        "Σ budgets × methods per image.\n\n" + t_exp
    )


if __name__ == "__main__":
    args = sys.argv[1:]
    n = int(args[args.index("--images") + 1]) if "--images" in args else None
    print(main("--quick" in args, "--oracle" in args, n))
