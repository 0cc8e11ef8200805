"""Survival % per method and box of a run, on the images every method completed, as Markdown (issue 17 measurement).

Reads the run's main rows (:func:`vbl_robust.campaigns.metrics.main_rows`; nothing is evaluated) and keeps only
images for which every (method, box) job is stored, so that a run still in progress, or resumed across
sessions, compares the methods on the same images. One row per method, one column per box (by level); a cell
is ``survival % (breaches)``. Where the run holds a dense landscape grid (``reproduce spatial-2d``: the first
image), the found / true worst ratio of each method on that image follows.

``--with RUN2`` (repeatable) adds the main rows of other runs of the same experiment and seed (the same images:
checked by sample id) as more methods, labelled with their options where they have any (e.g. a variant run with
``--method-option georobust-a.vertices=true`` shows as ``georobust-a [vertices=True]``); only images completed in
every run count.

    python tools/survival_table.py runs/issue17_spatial2d [--with runs/issue17_vertices]
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import defaultdict

import numpy as np

from vbl_robust.campaigns import metrics as mx
from vbl_robust.campaigns.spec import CampaignSpec
from vbl_robust.campaigns.store import ResultStore


def _label(r) -> str:
    opts = ", ".join(f"{k}={v}" for k, v in sorted(dict(r.options).items()))
    return f"{r.method} [{opts}]" if opts else r.method


def _mean(values: list) -> float:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else float("nan")


def survival_markdown(run: str, others: tuple[str, ...] = ()) -> str:
    """The tables (Markdown) of the run directory or store ``run`` (with the main rows of ``others``)."""
    out: list[str] = []
    emit = out.append
    with ResultStore.open_existing(run) as store:
        spec = CampaignSpec.from_dict(store.campaign()["spec"])
        rows = mx.main_rows(store, spec, with_trace=False)
        land = store.jobs(kind="search", role="landscape", with_points=True, with_trace=False)
    for other in others:
        with ResultStore.open_existing(other) as store:
            ospec = CampaignSpec.from_dict(store.campaign()["spec"])
            more = mx.main_rows(store, ospec, with_trace=False)
        if (ospec.name, ospec.seed) != (spec.name, spec.seed):
            raise SystemExit(f"{other}: experiment {ospec.name} seed {ospec.seed}, not {spec.name} seed {spec.seed}")
        index = {r.sample_index: r.sample_id for r in rows}
        clash = sorted({r.sample_index for r in more if index.get(r.sample_index, r.sample_id) != r.sample_id})
        if clash:
            raise SystemExit(f"{other}: images {clash[:5]} differ from {run}'s (another image set)")
        rows += [dataclasses.replace(r, method=_label(r)) for r in more]
    keys = {(r.method, r.box_label) for r in rows}
    per_image: dict[str, set] = defaultdict(set)
    for r in rows:
        per_image[r.sample_id].add((r.method, r.box_label))
    done = sorted(s for s, k in per_image.items() if k == keys)
    rows = [r for r in rows if r.sample_id in done]
    lines = mx.summarize(rows, spec.eps_safe_m, by=("method", "box_label"))
    boxes = sorted({ln["box_label"]: ln["box_level"] for ln in lines}.items(), key=lambda kv: kv[1] or 0.0)
    methods = list(dict.fromkeys(ln["method"] for ln in lines))
    cell = {(ln["method"], ln["box_label"]): ln for ln in lines}
    emit(f"{run}: {len(done)} images completed by every method (of {len(per_image)} started); "
          f"ε_safe = {spec.eps_safe_m:g} m; cell = survival % (breaches)")
    emit("")
    emit("| method | " + " | ".join(b for b, _ in boxes) + " |")
    emit("|---|" + "---|" * len(boxes))
    for m in methods:
        vals = [f"{cell[(m, b)]['survival']:.1f} ({cell[(m, b)]['breaches']})" if (m, b) in cell else "–"
                for b, _ in boxes]
        emit(f"| {m} | " + " | ".join(vals) + " |")
    if len(methods) > 1:  # the union: an image breaches a box when any method found a breach there
        hit = defaultdict(set)
        for r in rows:
            if r.worst_m is not None and r.worst_m > spec.eps_safe_m:
                hit[r.box_label].add(r.sample_id)
        emit("| any of them | " + " | ".join(
            f"{100.0 * (len(done) - len(hit[b])) / len(done):.1f} ({len(hit[b])})" for b, _ in boxes) + " |")
        emit("")
        emit("Evaluations spent per job, mean over all jobs / over the jobs that found a breach (early stop after "
             "the batch that found it): " + "; ".join(
                 f"{m} {_mean([r.nfev for r in rows if r.method == m]):.0f} / "
                 f"{_mean([r.nfev for r in rows if r.method == m and (r.worst_m or 0) > spec.eps_safe_m]):.1f}"
                 for m in methods) + ".")
    for g in land:
        if g.points is None or not len(g.points) or g.sample_id not in done:
            continue
        xs, fs = g.points.xs, g.points.fs
        emit("")
        emit(f"Landscape grid on image {g.sample_id} ({len(fs)} points over {g.box_label}): found / true worst")
        emit("")
        emit("| method | " + " | ".join(b for b, _ in boxes) + " |")
        emit("|---|" + "---|" * len(boxes))
        here = {(r.method, r.box_label): r for r in rows if r.sample_id == g.sample_id}
        for m in methods:
            vals = []
            for b, _ in boxes:
                r = here.get((m, b))
                if r is None or r.box is None or r.worst_m is None:
                    vals.append("–")
                    continue
                box = r.box.box
                inside = np.all((xs >= box.lower - 1e-9) & (xs <= box.upper + 1e-9), axis=1)
                true = float(np.nanmax(fs[inside])) if inside.any() else float("nan")
                vals.append(f"{r.worst_m / true:.3f}" if true > 0 else "–")
            emit(f"| {m} | " + " | ".join(vals) + " |")
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--with", dest="others", action="append", default=[], help="another run of the same experiment")
    a = ap.parse_args()
    import sys

    sys.stdout.write(survival_markdown(a.run, tuple(a.others)))


if __name__ == "__main__":
    main()
