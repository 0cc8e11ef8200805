"""A stored run's tables as Markdown (``vbl-robust report RUN --format md``, ``vbl-robust zones RUN --format md``).

Everything is read from the store; nothing is evaluated. Only images whose every main job is stored count, so a
run still in progress (or resumed across sessions) compares its methods on the same images.

* :func:`survival_markdown` — survival % with its exact 95 % interval (breaches, and their kinds: misleading /
  flagged) per method and box (and budget, where the run has several:
  the runtime experiments), the union "any of them", evaluations
  spent, and where the run holds a dense landscape grid the found / true worst ratio of each method;
  ``others`` adds the main rows of other runs of the same experiment and seed as more methods (labelled with
  their options, e.g. ``georobust-a [vertices=True]``);
* :func:`families_markdown` — the families ranking of a ``reproduce families`` run (the report's families
  section as a table);
* :func:`zones_markdown` — vulnerability-zone fractions per method and box, over all jobs and over the jobs that
  found no breach;
* :func:`compare_markdown` — two runs of the same images paired per image (a model before and after
  ``vbl-robust harden``): survival before / after, the images fixed and newly breached, exact McNemar p.
"""

from __future__ import annotations

import dataclasses
import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..analysis import readoff as ro
from ..analysis.breach import breached_images, not_measured_lines
from ..analysis.levels import ANY_METHOD, family_of, family_profile, rank_families
from ..analysis.summary import Summary, columns, summarize
from ..specs.campaign import CampaignSpec
from ..stats import Rate
from ..store.core import ResultStore

__all__ = ["compare_markdown", "families_markdown", "risk_markdown", "survival_markdown", "zones_markdown"]


def esc_md(text: object) -> str:
    """``text`` safe in a Markdown line or table cell: ``|`` escaped, ``<`` and ``>`` as entities (a name from data
    never becomes markup or a column)."""
    return str(text).replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace("|", "\\|")


def _table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    cells = [[esc_md(c) for c in r] for r in rows]
    return ["| " + " | ".join(map(esc_md, head)) + " |", "|" + "---|" * len(head),
            *("| " + " | ".join(r) + " |" for r in cells)]


def _labelled(r) -> str:
    opts = ", ".join(f"{k}={v}" for k, v in sorted(dict(r.options).items()))
    return f"{r.method} [{opts}]" if opts else r.method


def _mean(values: list) -> float:
    vals = [v for v in values if v is not None]
    return float(np.mean(vals)) if vals else float("nan")


def _kinds(line: Summary) -> str:
    """``"misleading / flagged"`` breach counts of a summary line (``?`` when unknown)."""
    return "? / ?" if line.misleading is None else f"{line.misleading} / {line.flagged}"


def _read(run: str | Path):
    with ResultStore.open_existing(run) as store:
        spec = store.spec()
        rows = ro.main_rows(store, spec, with_trace=False)
        land = store.jobs(kind="search", role="landscape", with_points=True, with_trace=False)
    return spec, rows, land


def _unmeasured(run: str | Path, unit: str) -> list[str]:
    """The run's jobs not measured, as Markdown lines (none when every job was measured)."""
    with ResultStore.open_existing(run) as store:
        every = store.jobs(with_trace=False)
    lines = not_measured_lines(every, len(every), unit)
    return [f"**{esc_md(lines[0])}**", *(f"- {esc_md(line)}" for line in lines[1:]), ""] if lines else []


def _progress(run: str | Path) -> list[str]:
    """A line when the store holds fewer jobs than its last run planned — a run writing it now, or one stopped
    before its end — so a partial table is never read as the whole run; none otherwise."""
    from ..specs.kinds import RunStatus

    with ResultStore.open_existing(run) as store:
        runs = store.runs()
        stored = store.count()
    planned = int(runs[-1].provenance.jobs_total or 0) if runs else 0
    if not runs or stored >= planned:
        return []
    if runs[-1].status == RunStatus.RUNNING:
        return [f"**Run in progress: a run is still writing this store; {stored} of {planned} planned jobs stored "
                "so far, the table holds the images every method has completed.**", ""]
    return [f"**Incomplete: {stored} of {planned} planned jobs stored (the last run {esc_md(runs[-1].status)}); the "
            "table holds the images every method completed; rerun the command to resume.**", ""]


def _read_alike(run: str | Path, spec: CampaignSpec, rows: Sequence, other: str | Path):
    """``other``'s spec and main rows, ``ValueError`` unless it is ``run``'s experiment and seed on its images."""
    from .compare import check_alike

    ospec, more, _ = _read(other)
    check_alike(run, spec, rows, other, ospec, more)
    return ospec, more


def risk_markdown(run: str | Path) -> str:
    """A risk run's failure probability per estimator and box as a Markdown table
    (:func:`~vbl_robust.analysis.tables.risk_records`, what ``--format csv|json`` print), each estimate with its
    interval, and the run's jobs not measured."""
    from ..analysis.tables import risk_records

    with ResultStore.open_existing(run) as store:
        records = risk_records(store)
    if not records:
        raise ValueError(f"{run}: no risk jobs stored yet")
    rows = [(r["method"], r["box_label"], str(r["images"]),
             f"{r['p_fail']:.4g} [{r['p_fail_ci_low']:.4g}, {r['p_fail_ci_high']:.4g}]",
             f"{r['tau']:g}", f"{r['holds']} / {r['violated']} / {r['undecided']}", str(r["not_measured"]),
             str(r["evaluations"])) for r in records]
    level = f"{100 * records[0]['ci_level']:g} %"
    head = f"{run}: failure probability per image under the run's distribution of θ, with its {level} interval"
    return "\n".join([esc_md(head), "", *_table(
        ("estimator", "box", "images", f"P(fail) [{level}]", "τ", "holds / violated / undecided", "not measured",
         "evaluations"), rows), "", *_unmeasured(run, "image")])


def survival_markdown(run: str | Path, others: Sequence[str | Path] = ()) -> str:
    """The survival tables of the run directory or store ``run`` (module docstring); ``ValueError`` when an other
    run is not the same experiment, seed and images."""
    spec, rows, land = _read(run)
    for other in others:
        _, more = _read_alike(run, spec, rows, other)
        rows += [dataclasses.replace(r, method=_labelled(r)) for r in more]
    if not rows:
        raise ValueError(f"{run}: no search jobs stored yet")
    several, col = columns(rows)  # a column per box, or per box and budget (the runtime experiments)
    keys = {(r.method, col(r)) for r in rows}
    per_image: dict[str, set] = defaultdict(set)
    for r in rows:
        per_image[r.sample_id].add((r.method, col(r)))
    done = sorted(s for s, k in per_image.items() if k == keys)
    rows = [r for r in rows if r.sample_id in done]
    eps = spec.settings.eps_safe_m
    lines = summarize(rows, eps)

    def order(ln) -> tuple:  # boxes by size, then time budgets before evaluation budgets, each ascending
        def num(v: float) -> float:
            return math.inf if math.isnan(v) else v
        return (ln.box_level or 0.0, math.isnan(ln.max_seconds), num(ln.max_seconds), num(ln.max_evals))

    ordered = sorted(lines, key=order)
    cols = list(dict.fromkeys(col(ln) for ln in ordered))
    boxes = list(dict.fromkeys(ln.box_label for ln in ordered))
    one = f"{boxes[0]}, " if several and len(boxes) == 1 else ""  # one box: the columns name only the budgets
    heads = [c.removeprefix(one) for c in cols]
    methods = list(dict.fromkeys(ln.method for ln in lines))
    cell = {(ln.method, col(ln)): ln for ln in lines}
    where = f"; box {boxes[0]}" if one else ""
    out = [f"{run}: {len(done)} {spec.unit}s measured by every method (of {len(per_image)} started); "
           f"ε_safe = {eps:g} m{where}; cell = survival % [exact 95 % interval] (breaches)", "",
           *_progress(run), *_unmeasured(run, spec.unit)]
    table = [[m, *(f"{cell[(m, c)].survival_rate.text(1, percent=False)} ({cell[(m, c)].breaches})"
                   if (m, c) in cell else "–" for c in cols)] for m in methods]
    kinds = [[m, *(_kinds(cell[(m, c)]) if (m, c) in cell else "–" for c in cols)] for m in methods]
    if len(methods) > 1 and done:  # the union: an image breaches a column when any method found a breach there
        hit, silent = {}, {}
        for c in cols:
            hit[c], silent[c], _ = breached_images([r for r in rows if col(r) == c], eps)
        table.append(["any of them", *(f"{Rate(len(done) - len(hit[c]), len(done)).text(1, percent=False)} "
                                       f"({len(hit[c])})" for c in cols)])
        kinds.append(["any of them", *(f"{len(silent[c])} / {len(hit[c]) - len(silent[c])}" for c in cols)])
    out += _table(["method", *heads], table)
    out += ["", "Breaches by kind, misleading / flagged only: misleading = a confident pose (confidence ≥ τ_conf, "
            "a PnP position) off by more than ε_safe; flagged = no detection, low confidence, PnP failed, … (the "
            "system knows it has no fix)", "", *_table(["method", *heads], kinds)]
    if len(methods) > 1 and not several:  # (with several budgets the budgets set the evaluations)
        out += ["", "Evaluations spent per job, mean over all jobs / over the jobs that found a breach: " + "; ".join(
            f"{m} {_mean([r.nfev for r in rows if r.method == m]):.0f} / "
            f"{_mean([r.nfev for r in rows if r.method == m and (r.worst_m or 0) > eps]):.1f}" for m in methods) + "."]
    for g in land:
        if g.points is None or not len(g.points) or g.sample_id not in done:
            continue
        xs, fs = g.points.xs, g.points.fs
        here = {(r.method, col(r)): r for r in rows if r.sample_id == g.sample_id}
        ratios = []
        for m in methods:
            vals = []
            for c in cols:
                r = here.get((m, c))
                if r is None or r.box is None or r.worst_m is None:
                    vals.append("–")
                    continue
                box = r.box.box
                inside = np.all((xs >= box.lower - 1e-9) & (xs <= box.upper + 1e-9), axis=1)
                true = float(np.nanmax(fs[inside])) if inside.any() else float("nan")
                vals.append(f"{r.worst_m / true:.3f}" if true > 0 else "–")
            ratios.append([m, *vals])
        out += ["", f"Landscape grid on image {g.sample_id} ({len(fs)} points over {g.box_label}): found / true worst",
                "", *_table(["method", *heads], ratios)]
    return "\n".join(out) + "\n"


def families_markdown(run: str | Path, series: str = "all") -> str:
    """The families ranking of a ``reproduce families`` run (``series="any"``: only the combined series, the
    ranking's basis); ``ValueError`` when the run holds no family jobs."""
    from . import rows as R
    from .figure_style import style
    from .sections import family_lines

    if series not in ("all", "any"):
        raise ValueError(f"series must be 'all' or 'any', got {series!r}")
    with ResultStore.open_existing(run) as store:
        spec = store.spec()
        main_rows = ro.main_rows(store, spec)
        ctx = R.Context(store, spec, Path(run), main_rows, store.samples())
        ref = R.reference(ctx, R.main_boxes(ctx))
    per_image_main = len({(r.method, r.box_label) for r in main_rows})
    counts: dict[str, int] = defaultdict(int)
    for r in main_rows:
        counts[r.sample_id] += 1
    ref_counts: dict[str, int] = defaultdict(int)
    for r in ref:
        ref_counts[r.sample_id] += 1
    ref_full = max(ref_counts.values(), default=0)
    done = {s for s, n in counts.items() if n == per_image_main and (not ref or ref_counts[s] == ref_full)}
    rows = [r for r in main_rows if r.sample_id in done and family_of(r) is not None]
    if not rows:
        raise ValueError(f"{run}: no complete family jobs (a `reproduce families` run)")
    profile = family_profile(rows + [r for r in ref if r.sample_id in done], spec.settings.eps_safe_m)
    order = rank_families(profile)
    lines = family_lines(profile, order)
    if series == "any":
        lines = [ln for ln in lines if ln["method"] == style(ANY_METHOD)["label"]]
    ks = [k for k in lines[0] if k.startswith("L") and k[1:].isdigit()] if lines else []

    def num(v) -> str:
        return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.0f}"

    out = [f"{run}: {len(done)} complete images of {len(counts)} started; reference rows per image {ref_full}; "
           f"ranking (most vulnerable first): {', '.join(order)}", ""]
    out += _table(["rank", "family", "method", "images", *[f"{k} %" for k in ks], "< 50 % at", "< 10 % at"],
                  [[str(ln["rank"]), ln["family"], ln["method"], str(ln["n"]), *(num(ln[k]) for k in ks),
                    ln["below_50"], ln["below_10"]] for ln in lines])
    return "\n".join(out) + "\n"


def zones_markdown(jobs: Sequence) -> str:
    """Zone fractions per method and box of :func:`vbl_robust.campaigns.replay.zones_of_run`'s jobs, with the basis their
    "ruled out" rests on (a given Lipschitz constant: sound; the searches' own estimates: not sound)."""
    from ..search.zones import CLASSES

    def basis(zm) -> str:
        if zm.basis == "sound":
            return f"sound under L = {zm.lipschitz} ({zm.norm}-norm, real units)"
        return "each search's own estimate (not sound)" if zm.basis == "estimate" else "no constant"

    groups: dict[tuple[str, str], list] = defaultdict(list)
    skipped: dict[str, int] = defaultdict(int)
    for j in jobs:
        if j.zones is None:
            skipped[j.method] += 1
        else:
            groups[(j.method, j.box_label or "")].append(j)

    def volume(label: str) -> float:  # boxes by size: the volume of the first job's box
        box = groups[next(k for k in groups if k[1] == label)][0].box
        return float(np.prod(np.asarray(box.upper) - np.asarray(box.lower)))

    rows = []
    for method, label in sorted(groups, key=lambda k: (k[0], volume(k[1]))):
        maps = [j.zones for j in groups[(method, label)]]
        hit = [zm.fractions["breached"] > 0 for zm in maps]
        clean = [zm for zm, h in zip(maps, hit, strict=True) if not h]
        rows.append([method, label, str(len(maps)), str(sum(hit)),
                     *(f"{100 * np.mean([zm.fractions[c] for zm in maps]):.1f}" for c in CLASSES),
                     *(f"{100 * np.mean([zm.fractions[c] for zm in clean]):.1f}" if clean else "–"
                       for c in CLASSES if c != "breached")])
    head = ["method", "box", "jobs", "breached jobs", *(f"% {c.replace('_', ' ')}" for c in CLASSES),
            *(f"% {c.replace('_', ' ')} (no-breach jobs)" for c in CLASSES if c != "breached")]
    bases = sorted({basis(j.zones) for j in jobs if j.zones is not None})
    out = [f"zones, basis: {'; '.join(bases) or 'none'}; skipped (no cover): "
           + (", ".join(f"{m} {n}" for m, n in sorted(skipped.items())) or "none"), "", *_table(head, rows)]
    return "\n".join(out) + "\n"


def compare_markdown(before: str | Path, after: str | Path) -> str:
    """Two runs of the same experiment and seed on the same images (e.g. a model before and after ``harden``),
    paired per image (:func:`vbl_robust.report.compare.paired_comparison`): per method and box, survival % before
    and after, the images fixed and newly breached and the exact McNemar p, then the union of all methods ("any of
    them") per box, over every image and per approach envelope. ``ValueError`` when the runs are not comparable."""
    from .compare import line_order, paired_comparison

    c = paired_comparison(before, after)
    out = [f"before: {before} ({c.detectors[0]}); after: {after} ({c.detectors[1]}) ({c.spec.name}, seed "
           f"{c.spec.seed}, ε_safe = {c.spec.settings.eps_safe_m:g} m); paired per image: fixed = breached before and not "
           "after, new = the other way, p = exact McNemar", ""]
    out += _table(["method", "box", "envelope", "images", "survival before % [95 % CI]", "survival after % [95 % CI]",
                   "fixed", "new breaches", "p"],
                  [[ln.method, ln.box, ln.envelope, str(ln.n), ln.before.text(1, percent=False),
                    ln.after.text(1, percent=False),
                    str(ln.fixed), str(ln.new), f"{ln.p_value:.4f}"] for ln in sorted(c.lines, key=line_order)])
    return "\n".join(out) + "\n"
