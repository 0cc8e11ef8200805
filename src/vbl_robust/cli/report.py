"""``vbl-robust report RUN``: rebuild the HTML report (and exports) of a run directory from its results store, or
print its tables as Markdown (``--format md``, :mod:`vbl_robust.report.markdown`);
``vbl-robust bundle ROOT --out DIR``: the committable bundle of a set of experiment runs
(:mod:`vbl_robust.paper.bundle`); ``vbl-robust merge SRC… --into RUN``: jobs computed elsewhere joined into one
run (:func:`vbl_robust.store.merge_runs`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from ..specs.kinds import JobKind
from . import options as o
from .common import check_writable, fail, one_line
from .run import unmeasured_ok

ReportOut = Annotated[Path | None, typer.Option("--out", help="Directory for report.html and figures/ (default: RUN).")]
Csv = o.variant(o.Csv, help="Also export the job rows to CSV.")
Parquet = o.variant(o.Parquet, help="Also export the job rows to Parquet.")
Format = Annotated[str, typer.Option(
    "--format", help="html (the report); md: print the survival tables (and a families run's ranking) as Markdown "
    "instead, on the images every method completed; csv or json: print the summary table, one row per method, box "
    "and budget (images, survivors, survival_pct, survival_ci_low, survival_ci_high, breaches, misleading, flagged, "
    "…).")]
With = Annotated[list[Path] | None, typer.Option("--with", help="--format md: another run of the same experiment and "
                                                 "seed whose methods join the table (repeatable).")]
Compare = Annotated[Path | None, typer.Option(
    "--compare", help="Another run of the same experiment, seed and images (e.g. after `vbl-robust harden`): "
    "survival before (RUN) and after, paired per image, with exact McNemar p — compare.html with the curves overlaid "
    "and the images that changed (in --out, default: that run's directory), or with --format md the table.")]


def report(
    run: o.StoredRun, out: ReportOut = None, csv: Csv = None, parquet: Parquet = None, fmt: Format = "html",
    others: With = None, compare: Compare = None, allow_unmeasured: o.AllowUnmeasured = False,
) -> None:
    """Regenerate a run's self-contained HTML report (figures, tables, provenance) from its store (a run directory,
    its results.sqlite, or a bundle's packed results.sqlite.xz, read through a temporary copy). Exit 1 when some job
    of the run was not measured, unless --allow-unmeasured, and when a row contradicts its own evaluations or
    digest (left out of the report; `vbl-robust verify` names it)."""
    held = _report(run, out, csv, parquet, fmt, others, compare)
    _unmeasured_exit(run, *(held or _held_back(run)), allow_unmeasured)


def _held_back(run: Path) -> tuple[str, frozenset[str], list, int]:
    """What the report leaves out of its numbers: the unit, the rows inconsistent with their evaluations or digests,
    the jobs the tool could not measure, and the number of the other jobs."""
    from vbl_robust.campaigns.verify import screen
    from vbl_robust.store.core import ResultStore

    with one_line(), ResultStore.open_existing(run, points_on_demand=True) as store:
        unit = store.spec().unit if store.holds_campaign() else "image"
        bad = screen(store).inconsistent
        missing = store.jobs(with_trace=False, measured=False)  # of the others only their number
        return unit, bad, missing, store.count() - len(bad)


def _unmeasured_exit(run: Path, unit: str, bad: frozenset[str], missing: list, total: int,
                     allow_unmeasured: bool) -> None:
    """The jobs of ``run`` the tool could not measure, on standard error, and exit 1 unless ``allow_unmeasured``;
    the rows inconsistent with their evaluations or digests (not used), on standard error too."""
    if bad:
        typer.secho(f"{run}: {len(bad)} job row(s) inconsistent — not used (vbl-robust verify {run} names them)",
                    err=True, fg=typer.colors.YELLOW)
    # a row that contradicts itself: never exit 0
    if not unmeasured_ok(missing, unit, allow_unmeasured, total=total) or bad:
        raise typer.Exit(1)


def _report(run: Path, out: Path | None, csv: Path | None, parquet: Path | None, fmt: str, others: list[Path] | None,
            compare: Path | None) -> tuple[str, frozenset[str], list, int] | None:
    """Write or print what ``fmt`` asks for; the HTML report returns what it left out of its numbers
    (:func:`_held_back`, read before it: a large store's rows and the gallery's torch are not held yet)."""
    from vbl_robust.analysis.tables import export
    from vbl_robust.paper.experiments import EXPERIMENT_TITLES
    from vbl_robust.report.build import build_report
    from vbl_robust.store.core import ResultStore

    if fmt not in ("html", "md", "csv", "json"):
        fail(f"--format {fmt}: choose html, md, csv or json")
    if fmt in ("csv", "json"):
        if out is not None or csv is not None or parquet is not None or others or compare is not None:
            fail(f"--format {fmt} prints the summary table: --out, --csv, --parquet, --with and --compare "
                 "belong to the other formats")
        _summary(run, fmt)
        return None
    if fmt == "md":
        if out is not None or csv is not None or parquet is not None:
            fail("--format md prints to standard output: --out, --csv and --parquet belong to --format html")
        typer.echo(_markdown(run, others or [], compare), nl=False)
        return None
    if others:
        fail("--with belongs to --format md")
    if out is not None and out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file; the report goes into a directory (report.html and figures/)")
    if compare is not None:
        if csv or parquet:
            fail("--csv and --parquet export one run: not with --compare")
        from vbl_robust.report.compare import compare_html

        with one_line():
            typer.echo(f"compare: {compare_html(run, compare, out)}")
        return None
    for option, target in (("--csv", csv), ("--parquet", parquet)):
        if target is not None:
            check_writable(option, target)
    held = _held_back(run)
    with one_line():
        path = build_report(run, out, titles=EXPERIMENT_TITLES)
        if csv or parquet:
            with ResultStore.open_existing(run, points_on_demand=True) as store:
                for p in (csv, parquet):
                    if p is not None:
                        typer.echo(f"exported {export(store, p)}")
    typer.echo(f"report: {path}")
    return held


Root = Annotated[Path, typer.Argument(help="Directory of experiment run directories (the --out of reproduce "
                                      "paper|all).")]
BundleOut = Annotated[Path, typer.Option("--out", help="Bundle directory (e.g. results/paper).")]
Reproduction = Annotated[Path | None, typer.Option(
    "--reproduction", help="A Markdown file (REPRODUCTION.md) whose part between '<!-- bundle:begin -->' and "
    "'<!-- bundle:end -->' is replaced by the claims and status tables.")]
Stores = Annotated[bool, typer.Option("--stores", help="Also a compact copy of each store (results.sqlite.xz), from "
                                      "which `reproduce --resume-from DIR` resumes an unfinished run elsewhere.")]


Detector = Annotated[list[str] | None, typer.Option(
    "--detector", help="LABEL=DIR: the same experiments run with another detector (DIR holds one run directory, or "
    "bundled experiment, per experiment); repeatable. The bundle then compares the claims across the detectors "
    "(detectors.md, the index, --reproduction).")]
DetectorLabel = Annotated[str, typer.Option("--detector-label", help="With --detector: the label of ROOT's own "
                                            "detector in the comparison.")]


def bundle(root: Root, out: BundleOut, reproduction: Reproduction = None, stores: Stores = False,
           detector: Detector = None, detector_label: DetectorLabel = "this bundle's detector") -> None:
    """Write a results bundle: per experiment the job table (Parquet), the report and the provenance, and a
    status table; runs still in progress are bundled as they stand (rerun to refresh)."""
    from vbl_robust.paper.bundle import write_bundle

    if out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file; a bundle is a directory")
    detectors = _detectors(root, detector_label, detector or [])
    with one_line():
        totals = write_bundle(root, out, reproduction=reproduction, stores=stores, detectors=detectors)
    for name, t in totals.items():
        typer.echo(f"{name}: {t['jobs_done']} of {t['jobs_planned']} jobs, {t['images_with_jobs']} images")
    typer.echo(f"bundle: {out}")


def _detectors(root: Path, label: str, items: list[str]) -> dict[str, Path] | None:
    """``--detector LABEL=DIR`` items as label → root, ``root`` first under ``label``; None without items."""
    if not items:
        return None
    found = {label.strip(): root}
    for item in items:
        name, sep, where = item.partition("=")
        name = name.strip()
        if not sep or not name or not where.strip():
            fail(f"--detector {item}: expected LABEL=DIR")
        if name in found:
            fail(f"--detector {item}: the label {name!r} is given twice (--detector-label names ROOT's)")
        if not Path(where).is_dir():
            fail(f"--detector {item}: {where} is not a directory")
        found[name] = Path(where)
    return found


Sources = Annotated[list[Path], typer.Argument(help="Run directories, .sqlite files, or packed stores (.sqlite.xz, as "
                                               "`bundle --stores` writes them) computed elsewhere.")]
Into = Annotated[Path, typer.Option("--into", help="The run directory (or .sqlite file) they join; created when "
                                    "missing.")]


MergeTrust = o.variant(o.TrustModel, help="Allow joining a campaign whose detector names code (a factory's "
                       "module:callable, a .pt outside the package): the joined run would build it.")


def merge(sources: Sources, into: Into, trust_model: MergeTrust = False) -> None:
    """Copy into one run the jobs that other runs of the same campaign and detector computed (another machine,
    a GPU, a cluster without a shared disk): rows it lacks, their samples and runs; rows it holds stay. Refused
    while a run writes it, and for a detector that names code unless --trust-model."""
    from vbl_robust.campaigns.verify import screen
    from vbl_robust.store.merge import MergeReport, merge_runs, store_file

    def merged(report: MergeReport) -> None:
        part = report.sources[-1]
        typer.echo(f"{part.source}: {part.copied} job rows merged, {part.already} already in {report.into}"
                   + (f"; {part.inconsistent} inconsistent — not merged (vbl-robust verify {part.source} names them)"
                      if part.inconsistent else ""))

    same = [s for s in sources if store_file(s).resolve() == store_file(into).resolve()]
    if same:  # merging a run into itself copies nothing and would open it for writing
        fail(f"merge {same[0]} --into {into}: a run cannot be merged into itself")
    with one_line(ValueError, OSError):
        done = merge_runs(sources, into, trust=trust_model, progress=merged,
                          left_out=lambda store: screen(store).inconsistent)  # rows contradicting themselves
    if len(done.code_versions) > 1:  # runs of other code versions joined: say which
        typer.echo(f"code versions joined in {done.into}: {', '.join(done.code_versions)}")


def _summary(run: Path, fmt: str) -> None:
    """The run's summary table (:func:`vbl_robust.analysis.tables.summary_table`: survival, or a risk run's
    failure probability per estimator) on standard output."""
    from vbl_robust.analysis.tables import summary_table, write_records
    from vbl_robust.store.core import ResultStore

    with one_line(), ResultStore.open_existing(run) as store:
        records, columns = summary_table(store)
    write_records(records, columns, fmt, sys.stdout)


def _markdown(run: Path, others: list[Path], compare: Path | None) -> str:
    from vbl_robust.report.markdown import (
        compare_markdown,
        families_markdown,
        risk_markdown,
        survival_markdown,
    )
    from vbl_robust.store.core import ResultStore

    with one_line():
        if compare is not None:
            return compare_markdown(run, compare)
        with ResultStore.open_existing(run) as store:
            spec = store.spec()
        if any(b.kind == JobKind.RISK for b in spec.blocks):
            if others:
                fail("--with: a risk run's table has no other runs beside it")
            return risk_markdown(run)
        text = survival_markdown(run, others)
        if spec.name == "families":
            text += "\n" + families_markdown(run)
    return text
