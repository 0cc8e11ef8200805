"""Peak memory of ``vbl-robust report`` and ``bundle --stores`` against the size of the store they read (issue 59:
a 1 GB store read within 1 GB).

A store of any size is made from a real one (a paper run's packed store by default) by copying its campaign, its
runs and every job row ``--copies`` times, each copy on samples of its own (``<id>~k``), through the store's own
writing API: every copied row gets its digest, so ``vbl-robust verify`` passes on the result and the report reads
every row as measured. The copies' images are not in any dataset, so the worst-case gallery shows their stored facts
alone; the original samples keep their pictures.

Then each command runs in a child process under ``/usr/bin/time -v``; the table gives the store's size and the peak
resident set of each, with the wall time. Run one at a time, nothing else heavy beside it::

    python benchmarks/report_memory.py --copies 1 8 32 --out results/bench/report_memory.md
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_store(source: Path, copies: int, out: Path) -> Path:
    """``out/results.sqlite``: ``source``'s campaign with every sample and job row ``copies`` times."""
    from vbl_robust.digest import digest
    from vbl_robust.store.core import ResultStore

    out.mkdir(parents=True, exist_ok=True)
    with ResultStore.open_existing(source) as src, ResultStore(out / "results.sqlite") as dst:
        camp = src.require_campaign()
        dst.bind_campaign(camp.name, camp.spec.to_dict(), dict(camp.detector))
        samples = src.samples()
        contents = src.contents()
        n = len(samples)
        with dst.transaction():
            for run in src.runs():
                dst.insert_run(dataclasses.replace(run, run_id=None))
        for k in range(copies):
            def sid(s: str, k: int = k) -> str:
                return s if k == 0 else f"{s}~{k}"

            with dst.transaction():
                dst.insert_samples(dataclasses.replace(r, sample_id=sid(r.sample_id),
                                                       sample_index=r.sample_index + k * n) for r in samples.values())
                dst.insert_contents([(sid(c[0]), *c[1:]) for c in contents])
            batch = []
            for r in src.jobs(with_points=True, with_trace=True):
                if k:  # a job of its own: key and chain (the budgets of one search) told apart from the original's
                    r = dataclasses.replace(r, key=digest({"key": r.key, "copy": k}, 40), sample_id=sid(r.sample_id),
                                            sample_index=r.sample_index + k * n,
                                            chain=None if r.chain is None else f"{r.chain}~{k}")
                batch.append(r)
                if len(batch) >= 200:
                    dst.commit(batch)
                    batch = []
            dst.commit(batch)
    return out / "results.sqlite"


def peak(cmd: list[str]) -> tuple[float, float, int]:
    """(peak RSS in MB, wall seconds, exit code) of ``cmd`` run under ``/usr/bin/time -v``."""
    t0 = time.perf_counter()
    p = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True,
                       env={**os.environ, "MPLBACKEND": "Agg", "YOLO_OFFLINE": "1"})
    wall = time.perf_counter() - t0
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    if p.returncode:
        sys.stderr.write(p.stderr[-2000:])
    return (int(m.group(1)) / 1024 if m else float("nan")), wall, p.returncode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--source", type=Path, default=ROOT / "results/paper/distance-profile",
                    help="a run directory or store to copy (default: the paper's distance profile)")
    ap.add_argument("--copies", type=int, nargs="+", default=[1, 8, 32])
    ap.add_argument("--out", type=Path, help="write the table here (Markdown) as well as printing it")
    ap.add_argument("--keep", type=Path, help="build the stores under this directory and keep them")
    args = ap.parse_args()
    from vbl_robust.store.core import ResultStore

    exe = str(Path(sys.executable).with_name("vbl-robust"))
    lines = ["| copies | jobs | store MB | report peak RSS MB | report s | bundle --stores peak RSS MB | bundle s |",
             "|---:|---:|---:|---:|---:|---:|---:|"]
    base = args.keep or Path(tempfile.mkdtemp(prefix="vbl-robust-memory-"))
    try:
        for c in args.copies:
            with ResultStore.open_existing(args.source) as s:
                name = s.require_campaign().name
            run = base / f"copies{c}" / name  # bundle reads ROOT/<experiment>/results.sqlite
            if not (run / "results.sqlite").is_file():
                build_store(args.source, c, run)
            with ResultStore.open_existing(run) as s:
                jobs = s.count()
            size = (run / "results.sqlite").stat().st_size / 2**20
            rep = peak([exe, "-q", "report", str(run), "--out", str(base / f"report{c}")])
            bun = peak([exe, "-q", "bundle", str(run.parent), "--out", str(base / f"bundle{c}"), "--stores"])
            lines.append(f"| {c} | {jobs} | {size:.0f} | {rep[0]:.0f}{'' if rep[2] == 0 else f' (exit {rep[2]})'} | "
                         f"{rep[1]:.0f} | {bun[0]:.0f}{'' if bun[2] == 0 else f' (exit {bun[2]})'} | {bun[1]:.0f} |")
            print(lines[-1], flush=True)
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == "__main__":
    main()
