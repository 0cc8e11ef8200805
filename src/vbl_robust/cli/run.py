"""Running a campaign from the command line: its settings (clock, workers, executor), the run into
``--out/results.sqlite`` with a rich progress bar (:func:`vbl_robust.campaigns.runner.run_campaign`), the summary
table, the exports and the report; the images it runs on (used by audit, demo, risk, reproduce and truth, through
:mod:`.requests`).

The library modules behind the run (the runner, the store, the detector, the samples, the report) import torch, and
rich takes 50 ms: they are imported inside the functions that use them, so that ``vbl-robust --help`` stays
instant."""

from __future__ import annotations

import fcntl
import math
import os
from pathlib import Path
from typing import Any

import typer

from ..specs.kinds import RunStatus
from .common import check_names, check_writable, fail, one_line
from .config import record_configuration
from .options import DEFAULT_IMAGES


def check_executor(executor: str, address: str | None) -> None:
    """``--executor`` and ``--address`` checked before any work (a Ray address must answer), or one line."""
    from vbl_robust.campaigns.runner import check_executor as check

    with one_line(ValueError):
        check(executor, address)


def run_settings(spec: Any, clock: str, device: str, workers: int) -> tuple[Any, int]:
    """``spec`` on the clock the user chose (``auto``: process time on a CPU, wall time on a GPU) and the worker
    count (0: :func:`~vbl_robust.campaigns.runner.default_workers`); a bad value fails with one line."""
    from vbl_robust.campaigns.runner import default_workers
    from vbl_robust.search.base import CLOCKS

    if clock == "auto":
        clock = "process" if device == "cpu" else "wall"
    if clock not in CLOCKS:
        fail(f"--clock must be auto, {' or '.join(sorted(CLOCKS))}, got {clock!r}")
    if workers < 0:
        fail(f"--workers must be >= 0 (0 = one per core), got {workers}")
    with one_line(ValueError):
        return spec.with_settings(clock=clock), workers or default_workers()


def run_with_progress(spec: Any, samples: list, out: Path, detector: Any, *, executor: str, address: str | None,
                      source: dict, config: dict, quiet: bool = False, workers: int = 1, wait: bool = False,
                      retry_failed: bool = False, allow_unmeasured: bool = False) -> Any:
    """Run ``spec`` into ``out/results.sqlite`` with a rich progress bar (``workers`` processes for the local
    executor; ``wait``: wait for another run writing the same store instead of refusing; ``allow_unmeasured``: run
    past images that cannot be read, whose jobs are then not measured, instead of refusing the run); returns the
    run summary."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from vbl_robust.campaigns.precheck import check_run
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.store.core import ResultStore

    with one_line(ValueError):
        spec.check()  # before anything is created or run
        spec.check_samples(samples)
        # images readable at their size (or, allowed, left to the run: an unreadable one is not measured), methods
        # fit for the detector
        check_run(spec, samples, detector, images=not allow_unmeasured)
    build_detector(detector)
    with one_line(ValueError):
        check_store(out, spec, samples, detector, wait=wait)  # the store there accepts this run, read only
    if allow_unmeasured:
        from vbl_robust.data.check import first_problem  # pymap3d behind it: not for ``--help``

        if problem := first_problem(samples):
            typer.secho(f"warning: {problem}; their jobs will be not measured (--allow-unmeasured)",
                        fg=typer.colors.YELLOW, err=True)
    made = _missing(out) + ([] if (out / "results.sqlite").exists() else [out / "results.sqlite"])
    with one_line(ValueError, OSError, prefix=f"--out {out}: "):
        out.mkdir(parents=True, exist_ok=True)
        ResultStore(out / "results.sqlite").close()  # a store that cannot be opened fails here, in one line
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("jobs"),
               TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), TextColumn("{task.fields[status]}"))
    started = []  # the run began (its store accepted it): its configuration is recorded, nothing is undone
    with ResultStore(out / "results.sqlite") as store, Progress(*columns, disable=quiet, transient=False) as bar:
        task = bar.add_task(spec.name, total=None, status="")

        def on_progress(p: Any) -> None:
            if not started:
                started.append(True)
                record_configuration()
            bar.update(task, total=p.total, completed=p.done,
                       status=f"breaches {p.breaches}"
                       + (f", not measured {p.not_measured}" if p.not_measured else "")
                       + (f" ({p.skipped} resumed)" if p.skipped else ""))

        try:
            summary = run_campaign(spec, samples, store, detector=detector, executor=executor, workers=workers,
                                   address=address, progress=on_progress, dataset_source=source, config=config,
                                   wait=wait, retry_failed=retry_failed, precheck=False)
        except (ValueError, FileNotFoundError) as exc:
            if not started:  # refused before it began (e.g. another run took the store meanwhile)
                store.close()
                _remove(made)
            fail(str(exc))
        except KeyboardInterrupt:
            bar.stop()
            fail(f"interrupted; finished jobs are saved in {out / 'results.sqlite'}: rerun the same command to resume",
                 code=130)
    return summary


def build_detector(detector: Any) -> None:
    """Build the run's detector once in this process before anything is stored (a worker process builds its own;
    built detectors are cached), so that a model which cannot be loaded is refused in one line, not found by the
    run after its store was made."""
    from vbl_robust.campaigns.work import detector_for

    try:
        detector_for(detector)
    except (ValueError, FileNotFoundError) as exc:
        fail(str(exc))
    except Exception as exc:  # noqa: BLE001 - a user's model or plugin failing to load: one line, exit 2
        fail(f"the detector {detector.name} cannot be built: {type(exc).__name__}: {one_line_text(exc)}")


def one_line_text(exc: BaseException) -> str:
    """The first line of ``exc``'s message (a library's multi-line error, shown as one line)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def check_store(out: Path, spec: Any, samples: list, detector: Any, *, wait: bool = False) -> None:
    """``ValueError`` when the store in ``out`` (if any) would refuse this run: another run is writing it (unless
    ``wait``), it holds results of another campaign or detector, or of other pixels of the same images — all read
    without writing, so a refusal leaves the run directory as it was."""
    from vbl_robust.campaigns.provenance import sample_fingerprint
    from vbl_robust.store.core import ResultStore
    from vbl_robust.store.identity import check_same

    path = out / "results.sqlite"
    if not path.is_file():
        return
    if not wait:
        _refuse_in_use(path)
    with ResultStore(path, readonly=True) as store:
        if not store.holds_campaign() or store.count() == 0:
            return
        check_same(path, store.require_campaign(), spec.to_dict(), detector.identity())
        store.changed_contents(samples)
        stored = store.samples()
    other = [s.id for s in samples if s.id in stored and stored[s.id].fingerprint != sample_fingerprint(s)]
    if other:  # the same names, another image (size, camera, geometry): the stored rows describe the old ones
        raise ValueError(f"{path}: samples {', '.join(other[:5])}{' …' if len(other) > 5 else ''} differ from those "
                         "its results were computed on (another size, camera or geometry under the same names); "
                         "run them into another --out")


def _refuse_in_use(path: Path) -> None:
    """``ValueError`` naming the PID when another process holds the store's writer lock
    (:class:`~vbl_robust.store.lock.WriterLock`), probed without writing the lock file."""
    lock = Path(f"{path}.lock")
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        return  # no lock file: nobody has written this store with a lock yet; the run's own lock decides
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        try:
            holder = lock.read_text().strip() or "another process"
        except OSError:
            holder = "another process"
        raise ValueError(f"{path.parent}: in use by PID {holder} (another run is writing this store); wait for it "
                         "to end (--wait) or write to another --out") from None
    finally:
        os.close(fd)  # releases the probe's lock


def _missing(out: Path) -> list[Path]:
    """``out`` and those of its parents that do not exist yet, innermost first."""
    return [p for p in (out, *out.parents) if not p.exists()]


def _remove(made: list[Path]) -> None:
    """Undo what a refused run created: its store file (with SQLite's companions and the writer lock), then the
    directories, innermost first, each only if empty."""
    for path in made:
        if path.name == "results.sqlite":
            for p in (path, *(path.with_name(path.name + x) for x in ("-wal", "-shm", ".lock"))):
                p.unlink(missing_ok=True)
    for path in sorted((p for p in made if p.name != "results.sqlite"), key=lambda p: len(p.parts), reverse=True):
        try:
            path.rmdir()
        except OSError:
            pass


def check_exports(csv: Path | None, parquet: Path | None, out: Path | None = None) -> None:
    """Refuse, before a run, an export the run could not write at its end: a ``--csv`` / ``--parquet`` name with
    another suffix, a directory, or a place that cannot be created or written; also an ``--out`` that is a file."""
    if out is not None:
        check_names("--out", out)
        if out.exists() and not out.is_dir():
            fail(f"--out {out}: is a file, not a run directory")
    for option, path, suffix in (("--csv", csv, ".csv"), ("--parquet", parquet, ".parquet")):
        if path is None:
            continue
        if path.suffix.lower() != suffix:
            fail(f"{option} {path}: the file name must end in {suffix}")
        check_names(option, path)
        check_writable(option, path)


def finish(out: Path, summary: Any, *, csv: Path | None, parquet: Path | None, report: bool, quiet: bool = False,
           allow_unmeasured: bool = False) -> bool:
    """Print the summary table, export, and write the HTML report; False when the run is incomplete or some job
    could not be measured (unless ``allow_unmeasured``): its caller ends with exit code 1 once it has done what else
    it can — a run that did not finish, or did not measure what it was asked to, never exits 0."""
    from vbl_robust.analysis.readoff import main_rows
    from vbl_robust.analysis.tables import export
    from vbl_robust.paper.experiments import EXPERIMENT_TITLES
    from vbl_robust.report.build import build_report
    from vbl_robust.store.core import ResultStore

    with ResultStore.open_existing(out) as store:
        spec = store.spec()
        # runs that read smaller budgets off their trace: per budget; jobs not measured counted apart
        rows = main_rows(store, spec, with_trace=False, measured_only=False)
        every = store.jobs(with_trace=False)
        for path in (csv, parquet):
            if path is not None:
                with one_line(ValueError):
                    export(store, path)
                typer.echo(f"exported {path}")
    if rows and not quiet:
        print_summary(spec, rows)
    status = (f"{summary.done} new jobs, {summary.skipped} already done, {summary.not_measured} not measured, "
              f"{summary.seconds:.0f} s")
    typer.echo(f"{spec.name}: {status}; results in {out / 'results.sqlite'}")
    if summary.status != RunStatus.FINISHED:
        typer.secho(f"run {summary.status}: rerun the same command to resume", fg=typer.colors.YELLOW, err=True)
    if report:
        typer.echo(f"report: {build_report(out, titles=EXPERIMENT_TITLES)}")
    return summary.status == RunStatus.FINISHED and unmeasured_ok(every, spec.unit, allow_unmeasured)


def unmeasured_ok(rows: list, unit: str, allow_unmeasured: bool, *, total: int | None = None) -> bool:
    """Tell the user what could not be measured (stderr, one line per reason) and whether the command may exit 0:
    yes when every job was measured, or ``--allow-unmeasured`` was given. ``total``: how many jobs there are, when
    ``rows`` are not all of them (default ``len(rows)``)."""
    from vbl_robust.analysis.breach import not_measured_lines

    lines = not_measured_lines(rows, len(rows) if total is None else total, unit)
    for line in lines:
        typer.secho(line, fg=typer.colors.RED if not allow_unmeasured else typer.colors.YELLOW, err=True)
    if lines and not allow_unmeasured:
        typer.secho("exit 1: fix the input or the method list and rerun with --retry-failed, or accept the rates "
                    "without these jobs with --allow-unmeasured", fg=typer.colors.RED, err=True)
    return not lines or allow_unmeasured


def print_summary(spec: Any, rows: list) -> None:
    """The survival table of a campaign's main rows (per method, and per box or budget where they vary) and its
    legend."""
    from rich.console import Console
    from rich.table import Table

    from vbl_robust.analysis.summary import summarize

    lines = summarize(rows, spec.settings.eps_safe_m)
    cols = ["method"] + [c for c in ("box_label", "budget_label") if len({getattr(ln, c) for ln in lines}) > 1]
    fixed = ", ".join(str(getattr(lines[0], c)) for c in ("box_label", "budget_label") if c not in cols)
    table = Table(title=f"{spec.name}: survival (worst error ≤ {spec.settings.eps_safe_m:g} m)" + (f" — {fixed}" if fixed else ""))
    heads = {"method": "method", "box_label": "box", "budget_label": "budget"}
    for c in cols:  # a method's name is never cut (georobust and georobust-av must stay apart)
        table.add_column(heads[c], no_wrap=c == "method", min_width=max(len(str(ln.method)) for ln in lines)
                         if c == "method" else None)
    empty = any(line.n_empty for line in lines)  # survivors never searched (no evaluation in a time budget)
    unmeasured = any(line.not_measured for line in lines)
    heads = ["n", "survival % [95 % CI]", *(["no eval in time"] if empty else []), "median (m)", "breaches",
             "failed evals", *(["unmeasured"] if unmeasured else [])]
    cells = []
    for line in lines:
        fe, med = line.failed_evals, line.median_worst_m
        kinds = "?" if line.misleading is None else f"{line.misleading} / {line.flagged}"
        cells.append([str(line.n), line.survival_rate.text(1, percent=False) if line.measured else "–",
                      *([str(line.n_empty)] if empty else []), "–" if math.isnan(med) else f"{med:.1f}",
                      f"{line.breaches} ({kinds})", "–" if fe is None else str(fe),
                      *([str(line.not_measured)] if unmeasured else [])])
    for j, col in enumerate(heads):  # values are never cut: a column is at least as wide as its widest value
        table.add_column(col, justify="right", min_width=max(len(c[j]) for c in cells))
    for line, row in zip(lines, cells, strict=True):
        table.add_row(*(str(getattr(line, c)) for c in cols), *row)
    Console().print(table)
    typer.echo(f"n: {spec.unit}s measured; median: of the worst errors found; failed evals: evaluations the pipeline "
               "failed (counted with the penalty); breaches: all (m / f): m misleading — a confident pose off by more "
               "than ε_safe; f flagged only — every breach a failure the system sees (no detection, low confidence, "
               "PnP failed …)" + ("; unmeasured: jobs the tool could not complete, in no rate (listed below)"
                                  if unmeasured else ""))
    if empty:
        typer.echo("no eval in time: searches that completed no evaluation within their time budget; they "
                   "found nothing and count as survivors")


def load_sequence_samples(source: str, frames: int, rate: float, seed: int, width: int, height: int,
                          ) -> tuple[list, dict]:
    """The approach sequences of ``--sequences`` (:func:`vbl_robust.campaigns.samples.load_sequences`), or one line."""
    from vbl_robust.campaigns.samples import load_sequences

    with one_line(ValueError, FileNotFoundError, RuntimeError):
        return load_sequences(source, frames=frames, rate_hz=rate, seed=seed, width=width, height=height)


def load(n: int | None, seed: int, lard: Path | None, width: int, height: int, *,
         default: int = DEFAULT_IMAGES) -> tuple[list, dict]:
    """``n`` samples (``None``: ``default``, or all rows of a smaller ``lard`` dataset), or one line."""
    from vbl_robust.campaigns.samples import load_samples

    with one_line(ValueError, FileNotFoundError, RuntimeError):  # RuntimeError: no pose fits a strip of an image
        return load_samples(default if n is None else n, seed, lard=lard, width=width, height=height,
                            at_most=n is None)
