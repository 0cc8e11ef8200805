"""Campaign costs: per-job overhead of the runner + store vs a bare search, and how long each of the paper's
experiments takes here on the shipped detector: ``reproduce --estimate``'s expectation beside the full-size run's
measured search time (from the committed bundle ``results/paper``).

Usage::

    python benchmarks/bench_campaigns.py [--quick] [--oracle]

The overhead is measured with the oracle detector (ground-truth corners, no network), which isolates the
runner's own cost; the estimate probes the shipped model (``--model default``, the two-stage design) — what the
bundle's run used — unless ``--oracle``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

BUNDLE = Path(__file__).resolve().parent.parent / "results" / "paper"
WORKERS = 2  # the reproduction's workers on this 2-core machine (one per core)


def _detectors(oracle_only: bool):
    from vbl_robust.detect.shipped import DetectorSpec

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

    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.campaigns.work import detector_for
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.search.api import maximize
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
    from vbl_robust.store.core import ResultStore

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


def durations(detector, bundle: Path, quick: bool) -> str:
    """Each paper experiment's expected duration (``reproduce --estimate``'s probe and rule: process clock, two
    workers) beside what its full-size run in ``bundle`` measured (the provenance totals of ``vbl-robust bundle``):
    how far the estimate can be trusted, and what the run costs."""
    import json

    from vbl_robust.campaigns.samples import load_samples
    from vbl_robust.paper.estimate import PROBE_IMAGES, Probe, expected_seconds, probe
    from vbl_robust.paper.experiments import EXPERIMENTS, PAPER, Options

    specs = {name: EXPERIMENTS[name].build(0, Options()).with_settings(clock="process") for name in PAPER}
    pr = probe(detector, list(specs.values()), load_samples(PROBE_IMAGES, 0)[0], seconds=1.0 if quick else 5.0,
               clock="process")
    lines = [f"Probe: {pr.rate:.1f} evaluations per CPU second black box, {pr.grad_rate:.1f} with a gradient; "
             f"{WORKERS} workers.\n",
             "| experiment | images | expected (h) | upper bound (h) | jobs measured | searches, measured (CPU h) | "
             "searches ÷ workers (h) | measured ÷ expected | wall of its runs (h) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    sums = {"t": 0.0, "ub": 0.0, "spent": 0.0, "wall": 0.0, "complete": True}
    for name, spec in specs.items():
        n = EXPERIMENTS[name].images
        t, ub = expected_seconds(spec, n, pr, WORKERS), expected_seconds(spec, n, Probe(pr.rate, pr.grad_rate), WORKERS)
        prov = bundle / name / "provenance.json"
        tot = json.loads(prov.read_text())["totals"] if prov.is_file() else None
        sums["t"] += t
        sums["ub"] += ub
        if tot is None or tot["clock"] != "process":
            sums["complete"] = False
            lines.append(f"| {name} | {n} | {t / 3600:.2f} | {ub / 3600:.2f} | – | – | – | – | – |")
            continue
        done = f"{tot['jobs_done']} / {tot['jobs_planned']}"
        spent = tot["search_s"] or tot["worker_s"]  # jobs without a search (PnP validation): their own time
        search = spent / 3600
        ratio = f"{spent / WORKERS / t:.2f}" if tot["jobs_done"] == tot["jobs_planned"] and t else "(partial)"
        lines.append(f"| {name} | {n} | {t / 3600:.2f} | {ub / 3600:.2f} | {done} | {search:.2f} | "
                     f"{search / WORKERS:.2f} | {ratio} | {tot['wall_s'] / 3600:.2f} |")
        sums["spent"] += spent
        sums["wall"] += tot["wall_s"]
        sums["complete"] &= tot["jobs_done"] == tot["jobs_planned"]
    if sums["complete"]:
        s = sums["spent"] / 3600
        lines.append(f"| **all** | | {sums['t'] / 3600:.2f} | {sums['ub'] / 3600:.2f} | | {s:.2f} | "
                     f"{s / WORKERS:.2f} | {sums['spent'] / WORKERS / sums['t']:.2f} | {sums['wall'] / 3600:.2f} |")
    return "\n".join(lines) + "\n"


def _convergence_spend(bundle: Path) -> str:
    """What the bundle's convergence jobs spent, for the note under the durations table ("" without its table)."""
    table = bundle / "convergence" / "jobs.parquet"
    if not table.is_file():
        return ""
    import pyarrow.parquet as pq

    nfev = [v for v in pq.read_table(table, columns=["nfev"]).column("nfev").to_pylist() if v is not None]
    if not nfev:
        return ""
    return (f"; its {len(nfev)} runs of GeoRobust spent {sum(nfev) / len(nfev):.0f} evaluations on average "
            f"(at most {max(nfev)}): 1-D DIRECT selects few rectangles per iteration")


def main(quick: bool = False, oracle_only: bool = False) -> str:
    import torch

    from vbl_robust.paper.experiments import CONVERGENCE_MAX_EVALS

    torch.set_num_threads(1)
    oracle, det = _detectors(oracle_only)
    cmd = "python benchmarks/bench_campaigns.py" + (" --quick" if quick else "") + (" --oracle" if oracle_only else "")
    t_over, _ = overhead(oracle, 1 if quick else 3, 20 if quick else 60)
    t_exp = durations(det, BUNDLE, quick)
    who = f"the shipped model ({_shipped_version()}two-stage, `--model default`)" if det.kind == "default" else \
        "the oracle detector"
    return (
        "## Campaigns: runner overhead and experiment durations\n\n"
        f"Command: `{cmd}`. Synthetic 1024 × 1024 approaches; 1 torch thread.\n\n"
        "### Per-job overhead of the runner and results store\n\n"
        "Oracle detector (ground-truth corners, no network), so that the runner's own cost is not hidden behind "
        "the network's.\n\n" + t_over +
        f"\n### Duration of the paper's experiments at their sizes, detector: {who}\n\n"
        "Expected: `vbl-robust reproduce paper --estimate`'s rule (a probe of the evaluation rates on the process "
        "clock, the breach shares of the first images, two workers; the upper bound spends every budget). Measured: "
        "the full-size run's searches in CPU hours, from the committed bundle `results/paper` (each experiment's "
        "`provenance.json`; `vbl-robust bundle` writes it), and that time split over the two workers — what an idle "
        "machine needs (the PnP validation has no search: its jobs' own time); the wall time of its runs also holds "
        "the sessions' other work. \"measured ÷ expected\" once an experiment is complete; the row \"all\" once "
        "every experiment is. The convergence experiment's expectation charges each image its evaluation cap "
        f"({CONVERGENCE_MAX_EVALS}){_convergence_spend(BUNDLE)}.\n\n" + t_exp
    )


if __name__ == "__main__":
    args = sys.argv[1:]
    print(main("--quick" in args, "--oracle" in args))
