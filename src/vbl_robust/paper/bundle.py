"""A results bundle: what a reader of a set of experiment runs needs, small enough to commit.

``write_bundle(root, out)`` reads every run directory ``root/<experiment>/results.sqlite`` (as ``reproduce paper``
or ``all`` writes them; a run still in progress is read as it stands) and writes, per experiment, into
``out/<experiment>/``:

- ``jobs.parquet``: the job table (:func:`~vbl_robust.analysis.tables.export`: one line per job and per read-off
  budget; traces and evaluated points stay in the store);
- ``report.html`` and ``figures/``: the report, showing its figures from that folder by relative path
  (``build_report(embed=False)``: the folder opens offline; a page of tens of kB instead of megabytes of base64,
  and a figure that did not change is the same file in git), with ``evidence.json`` and ``headline.png``;
- ``provenance.json``: the campaign spec and every run of the store (code version, model SHA-256, detector,
  dataset, options, seed, executor, workers, clock, started / finished, wall seconds), and the totals: jobs done
  of planned, images, worker seconds (the sum of the jobs' own seconds: CPU seconds when each worker has one
  thread) and search seconds;

and, with ``stores=True``, ``results.sqlite.xz``: a compact copy of the store (``VACUUM INTO`` then xz), from which
:func:`restore_store` lets a fresh checkout resume an unfinished run (``reproduce --resume-from``);

and ``out/status.md``: one line per experiment (jobs done / planned, images, wall and worker hours),
``out/claims.md``: the paper's claims checked on those stores (:mod:`vbl_robust.paper.claims`), and
``out/index.html``: the overall verdict and what was measured (data, model), the claims section, then one card
per experiment in the paper's order (a link to its report, its jobs done, the verdicts of the claims on it and its
headline figure). Names from the runs are escaped in every file (Markdown: :func:`~vbl_robust.report.markdown.esc_md`). With
``reproduction=PATH`` the part of that Markdown file between :data:`BEGIN` and :data:`END` is replaced by the
claims and status tables (the rest of it is prose kept as written). Without ``stores``
the SQLite stores are not copied (tens of MB; a packed store already in ``out`` is kept); rerunning the command that
made them regenerates them.

Atomic as a whole: everything is written into a staging directory beside ``out`` first and moved into ``out`` only
when complete (:func:`_publish`), so a bundle killed midway leaves the previous bundle as it was, never experiments
without their ``index.html`` or ``claims.md``.

:func:`refresh_bundle` rewrites the top files (and REPRODUCTION.md's generated part) of a committed bundle from its
own packed stores and provenance, without the run directories: after a change of the claims' rules; with
``reports=True`` it first rebuilds each experiment's report from its packed store (:func:`rebuild_report`): after
a change of the report. Neither reruns an experiment.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..atomic import atomic_write
from ..report.markdown import esc_md
from ..store.core import PACKED, STORE, ResultStore
from ..store.pack import pack_store
from ..store.rows import RunRecord
from .experiments import EXPERIMENT_TITLES

#: Markers of the generated part of a REPRODUCTION.md (:func:`write_bundle`).
BEGIN, END = "<!-- bundle:begin -->", "<!-- bundle:end -->"
#: What :func:`~vbl_robust.report.build.build_report` writes into an experiment's directory of a bundle.
REPORT_FILES = ("report.html", "figures", "evidence.json", "headline.png")


def run_dirs(root: Path, names: Sequence[str] | None = None) -> list[Path]:
    """The experiment run directories under ``root`` that hold a store, in ``names`` order (default: sorted)."""
    root = Path(root)
    if names is None:
        return sorted(p.parent for p in root.glob(f"*/{STORE}"))
    return [root / n for n in names if (root / n / STORE).is_file()]


def _wall_seconds(run: RunRecord, last_job: dict[int, str]) -> float:
    """A run's wall seconds. A run without ``seconds`` is still going or was killed before it could record its end
    (SIGKILL, a session's end): its wall time runs from its start to its last stored job (``last_job``: run id →
    ISO time of its newest job), not to now — a killed run's idle years must not count."""
    if run.seconds is not None:
        return float(run.seconds)
    started = dt.datetime.fromisoformat(run.started_at)
    last = last_job.get(run.run_id)
    if last is None:
        return 0.0
    return max(0.0, (dt.datetime.fromisoformat(last) - started).total_seconds())


def provenance(store: ResultStore) -> dict[str, Any]:
    """The store's campaign spec, runs and totals (see the module docstring)."""
    runs = store.runs()
    jobs = store.jobs(with_trace=False)
    last_job: dict[int, str] = {}
    for r in jobs:
        if r.run_id is not None and r.finished_at is not None:
            last_job[r.run_id] = max(last_job.get(r.run_id, r.finished_at), r.finished_at)
    planned = max((int(r.provenance.jobs_total or 0) for r in runs), default=0)
    campaign = store.require_campaign()  # the one error of a store nothing ran into (its report needs one too)
    return {
        "campaign": campaign.to_dict(),
        "runs": [r.to_dict() for r in runs],
        "totals": {
            "jobs_done": len(jobs),
            "jobs_planned": planned,
            "images": len(store.samples()),
            "images_with_jobs": len({r.sample_id for r in jobs}),
            "wall_s": sum(_wall_seconds(r, last_job) for r in runs),
            "worker_s": sum(float(r.job_s or 0.0) for r in jobs),
            "search_s": sum(float(r.search_s or 0.0) for r in jobs),
            "clock": campaign.spec.settings.clock,
            "workers": sorted({r.provenance.config.get("workers") for r in runs if r.provenance.config} - {None}),
        },
    }


def write_experiment(run: Path, out: Path, stores: bool = False, keep: Path | None = None) -> dict[str, Any]:
    """Bundle one run directory into ``out`` (created; with its packed store when ``stores``, else the packed store
    of the bundle ``keep`` — the experiment's previous bundle directory — when it has one); returns its provenance
    totals."""
    from ..analysis.tables import export
    from ..report.build import build_report

    out.mkdir(parents=True, exist_ok=True)
    with ResultStore.open_existing(run, points_on_demand=True) as store:  # bounded memory, whatever the store's size
        prov = provenance(store)
        export(store, out / "jobs.parquet")
        if stores:
            pack_store(store, out / PACKED)
        elif keep is not None and (keep / PACKED).is_file():
            shutil.copy2(keep / PACKED, out / PACKED)
    atomic_write(out / "provenance.json", json.dumps(prov, indent=1, sort_keys=True, default=str) + "\n")
    build_report(run, out, embed=False, titles=EXPERIMENT_TITLES)
    return prov["totals"]


def rebuild_report(experiment: Path) -> Path:
    """Rebuild a bundled experiment's report (:data:`REPORT_FILES`) from its own packed store, in place: built
    beside it first, then each file replaced (``figures/`` by two renames), a file the new report does not write
    removed; killed before that, the old report stays whole. Returns the report's path."""
    from ..report.build import build_report

    experiment = Path(experiment)
    stage = experiment.parent / f".{experiment.name}.report"
    shutil.rmtree(stage, ignore_errors=True)
    try:
        # reads <experiment>/results.sqlite.xz
        build_report(experiment, stage, embed=False, titles=EXPERIMENT_TITLES)
        for name in REPORT_FILES:
            new, target = stage / name, experiment / name
            if new.is_dir():
                _replace_dir(new, target)
            elif new.is_file():
                os.replace(new, target)
            elif target.is_dir():
                shutil.rmtree(target)
            else:
                target.unlink(missing_ok=True)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return experiment / "report.html"


def _publish(stage: Path, out: Path) -> None:
    """Move everything in ``stage`` into ``out``: each experiment directory replaces its old one by two renames (the
    old one is removed only once the new one is in place), then the top files, ``index.html`` last, each by an atomic
    replace. A bundle killed before this point leaves ``out`` as it was; one killed inside it (milliseconds) leaves
    each experiment whole, old or new."""
    out.mkdir(parents=True, exist_ok=True)
    entries = sorted(stage.iterdir(), key=lambda p: (p.is_file(), p.name == "index.html", p.name))
    for entry in entries:
        if entry.is_dir():
            _replace_dir(entry, out / entry.name)
        else:
            os.replace(entry, out / entry.name)


def _replace_dir(new: Path, target: Path) -> None:
    """``new`` moved to ``target`` by two renames: the old ``target`` is removed only once the new one is in
    place."""
    old = target.with_name(f".{target.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    if target.exists():
        target.rename(old)
    new.rename(target)
    shutil.rmtree(old, ignore_errors=True)

def status_markdown(totals: dict[str, dict[str, Any]]) -> str:
    """The per-experiment status table of a bundle (Markdown; names escaped, :func:`esc_md`): wall hours of its runs; worker hours (each job's wall
    time in its worker, waits for a shared core included); search hours on the campaign's clock (on the process
    clock: the CPU hours the searches took, what an idle machine would need)."""
    lines = ["| experiment | jobs done / planned | images | wall (h) | worker (h) | searches (h, on the clock) | clock "
             "| workers |", "|---|---|---|---|---|---|---|---|"]
    for name, t in totals.items():
        lines.append(f"| {esc_md(name)} | {t['jobs_done']} / {t['jobs_planned']} | {t['images_with_jobs']} of "
                     f"{t['images']} | {t['wall_s'] / 3600:.2f} | {t['worker_s'] / 3600:.2f} | "
                     f"{t.get('search_s', 0.0) / 3600:.2f} | {esc_md(t['clock'])} | "
                     f"{esc_md(', '.join(map(str, t['workers'])) or '–')} |")
    hours = {k: sum(t.get(k, 0.0) for t in totals.values()) / 3600 for k in ("wall_s", "worker_s", "search_s")}
    lines.append(f"| **all** | {sum(t['jobs_done'] for t in totals.values())} / "
                 f"{sum(t['jobs_planned'] for t in totals.values())} | | {hours['wall_s']:.2f} | {hours['worker_s']:.2f} "
                 f"| {hours['search_s']:.2f} | | |")
    return "\n".join(lines) + "\n"


def write_bundle(root: Path, out: Path, names: Sequence[str] | None = None,
                 reproduction: Path | None = None, stores: bool = False,
                 detectors: Mapping[str, Path] | None = None) -> dict[str, dict[str, Any]]:
    """Bundle every experiment run under ``root`` (those of ``names`` that exist) into ``out``; writes
    ``out/status.md``, ``out/claims.md`` and ``out/index.html`` (and the generated part of ``reproduction``) and
    returns the totals per experiment. ``detectors`` (label → root, the first being ``root``'s own detector): the
    same experiments run with other detectors, compared claim by claim (:mod:`.detectors`) in ``out/detectors.md``,
    the index and ``reproduction``. ``FileNotFoundError`` when there is no run; ``ValueError`` when
    ``reproduction`` lacks the markers (checked before any work)."""
    if Path(out).resolve() == Path(root).resolve():
        raise ValueError(f"--out {out}: the bundle goes beside the runs, not into their directory (it would replace "
                         "each run's report)")
    runs = run_dirs(root, names)
    if not runs:
        raise FileNotFoundError(f"{root}: no experiment run directory (<experiment>/{STORE}) found")
    text = _reproduction_text(reproduction) if reproduction is not None else None
    out = Path(out)
    stage = out.parent / f".{out.name}.staging"  # the whole bundle is written here, then published into out
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir(parents=True)
    try:
        read = _read_top(root, detectors)  # first: the experiments' reports load torch for their galleries
        totals = {run.name: write_experiment(run, stage / run.name, stores, keep=out / run.name) for run in runs}
        claims, compared = _write_top(stage, totals, root, detectors, read)
        _publish(stage, out)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    if text is not None:
        _write_reproduction(Path(reproduction), text, claims, status_markdown(_ordered(totals)), compared)
    return totals


def _ordered(totals: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    from .claims_page import paper_order

    return {n: totals[n] for n in paper_order(list(totals))}


def _read_top(root: Path, detectors: Mapping[str, Path] | None) -> tuple[list[Any], Any]:
    """What the bundle's top pages say, read from the stores: the claims of the stores under ``root`` and, with
    ``detectors``, the detectors' tables (:func:`~.detectors.detectors_tables`: every store read once). Read before
    the experiments are written: a large store's rows and the torch a report's gallery loads are not held at
    once."""
    from .claims import claims_of
    from .detectors import detectors_tables

    return claims_of(root), (detectors_tables(detectors) if detectors else None)


def _write_top(out: Path, totals: dict[str, dict[str, Any]], root: Path,
               detectors: Mapping[str, Path] | None, read: tuple[list[Any], Any]) -> tuple[str, str]:
    """Write ``out/status.md``, ``out/claims.md`` (the claims of the stores under ``root``, ``read`` by
    :func:`_read_top`), with ``detectors`` ``out/detectors.md``, and ``out/index.html`` (the experiments ``totals``
    names, in the paper's order); returns the claims' Markdown and the detectors' ("" without)."""
    from .claims_page import claims_html, claims_markdown, write_index
    from .detectors import detectors_html, detectors_markdown

    totals = _ordered(totals)
    checked, tables = read
    claims = claims_markdown(checked, str(root))
    atomic_write(out / "status.md", status_markdown(totals))
    atomic_write(out / "claims.md", claims)
    compared, extra = "", ""
    if detectors:
        compared = detectors_markdown(detectors, tables)
        atomic_write(out / "detectors.md", compared)
        extra = detectors_html(detectors, out, tables)
    write_index(out, list(totals), claims_html(checked, str(root)) + extra,
                {n: f"{t['jobs_done']} of {t['jobs_planned']} jobs, {t['images_with_jobs']} of {t['images']} "
                    f"images" for n, t in totals.items()}, claims=checked)
    return claims, compared


def _reproduction_text(reproduction: Path) -> str:
    """The text of a REPRODUCTION.md; ``ValueError`` when it lacks the markers of its generated part."""
    text = Path(reproduction).read_text()
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ValueError(f"{reproduction}: needs one {BEGIN} line followed by one {END} line")
    return text


def _write_reproduction(path: Path, text: str, claims: str, status: str, detectors: str = "") -> None:
    """Replace the generated part of ``text`` (a REPRODUCTION.md) by the claims and status tables (and the claims on
    several detectors, when given)."""
    head, rest = text.split(BEGIN)
    tail = rest.split(END)[1]
    compared = f"## The claims on several detectors\n\n{detectors}\n" if detectors else ""
    atomic_write(path, f"{head}{BEGIN}\n## The paper's claims, checked\n\n{claims}\n{compared}"
                       f"## Status of the runs\n\n{status}{END}{tail}")


def refresh_bundle(out: Path, reproduction: Path | None = None, *, reports: bool = False,
                   detectors: Mapping[str, Path] | None = None) -> dict[str, dict[str, Any]]:
    """Rewrite a bundle's ``status.md``, ``claims.md`` and ``index.html`` (and the generated part of
    ``reproduction``) from what the bundle itself holds — each experiment's ``provenance.json`` totals and its
    packed store (:func:`~vbl_robust.paper.claims.claims_of` reads ``results.sqlite.xz``) — without rerunning
    anything: after a change of the claims' rules or of the index. With ``reports``, each experiment's report is
    first rebuilt from its packed store (:func:`rebuild_report`; an experiment without one keeps its report);
    ``detectors``: as :func:`write_bundle`'s (the first root is then ``out`` itself).
    ``FileNotFoundError`` when ``out`` holds no bundled experiment; ``ValueError`` when ``reproduction`` lacks the
    markers (checked first)."""
    out = Path(out)
    text = _reproduction_text(reproduction) if reproduction is not None else None
    totals = {}
    for prov in sorted(out.glob("*/provenance.json")):
        totals[prov.parent.name] = json.loads(prov.read_text())["totals"]
    if not totals:
        raise FileNotFoundError(f"{out}: no bundled experiment (<experiment>/provenance.json) found")
    read = _read_top(out, detectors)
    if reports:
        for name in totals:
            if (out / name / PACKED).is_file():
                rebuild_report(out / name)
    claims, compared = _write_top(out, totals, out, detectors, read)  # each file replaced atomically; the
    if text is not None:                                                  # experiments are left as they are
        _write_reproduction(Path(reproduction), text, claims, status_markdown(_ordered(totals)), compared)
    return totals


def _table_rows(source: Path) -> dict[tuple[str, str], dict[str, Any]]:
    """The flat job rows (:func:`~vbl_robust.analysis.tables.flat_rows`) of a run directory or store, or of a
    bundle's job table (an experiment directory of the bundle holding ``jobs.parquet``, or that file), by
    ``(key, budget_label)`` (a read-off budget shares its run's key)."""
    from ..analysis.tables import flat_rows

    source = Path(source)
    table = source / "jobs.parquet" if source.is_dir() and not (source / STORE).is_file() else source
    if table.suffix == ".parquet":
        if not table.is_file():
            raise ValueError(f"{source}: neither a results store nor a bundle's jobs.parquet")
        import pyarrow.parquet as pq

        rows = pq.read_table(table).to_pylist()
    else:
        with ResultStore.open_existing(source) as store:
            rows = flat_rows(store)[0]
    return {(r["key"], r["budget_label"]): r for r in rows}


def compare_runs(small: Path, big: Path, rel: float = 1e-3) -> dict[str, Any]:
    """Check that a smaller run reproduces a larger one's rows (``reproduce EXPERIMENT --images 3
    --check-against``): every row of ``small`` (a run directory or store) must be in ``big`` (a run directory or
    store, or a bundle's job table: :func:`_table_rows`) under the same key and budget. Rows of a time budget are
    counted but not compared (timings differ run to run). A row differs in one of two ways:

    - a **finding** changed (``differ``): the row is missing there, or its status or verdict differs — a breach
      found or lost, a job failed;
    - **numeric drift** (``drift``): the same finding, but the evaluation or iteration count, the worst point or
      the worst error (beyond ``rel``, relative) moved — what another CPU's kernels rounding differently do to a
      search whose tie-breaks then diverge. ``drift_m`` is the largest worst-error change (metres).

    Returns ``{"rows", "common", "differ": [keys…], "drift": [keys…], "drift_m": float}``."""
    rows_a, rows_b = _table_rows(small), _table_rows(big)
    differ, drift, drift_m = [], [], 0.0
    for (key, budget), r in rows_a.items():
        s = rows_b.get((key, budget))
        if s is None:
            differ.append(key)
            continue
        if r["max_seconds"] is not None:
            continue
        if any(r[c] != s.get(c) for c in ("status", "verdict")):
            differ.append(key)
            continue
        numeric = ["nfev", "nit", *(c for c in r if c.startswith("worst_") and c != "worst_m")]
        a, b = r["worst_m"], s["worst_m"]
        close = a == b or (a is not None and b is not None and abs(a - b) <= rel * max(1.0, abs(b)))
        if not close or any(r[c] != s.get(c) for c in numeric):
            drift.append(key)
            if a is not None and b is not None:
                drift_m = max(drift_m, abs(a - b))
    return {"rows": len(rows_a), "common": sum(k in rows_b for k in rows_a), "differ": differ, "drift": drift,
            "drift_m": drift_m}
