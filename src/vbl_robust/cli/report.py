"""``vbl-robust report RUN``: rebuild the HTML report (and exports) of a run directory from its results store;
``vbl-robust bundle ROOT --out DIR``: the committable bundle of a set of experiment runs
(:mod:`vbl_robust.campaigns.bundle`)."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import fail


def register(app: typer.Typer) -> None:
    @app.command()
    def report(
        run: Path = typer.Argument(..., help="Run directory (holding results.sqlite) or the .sqlite file."),
        out: Path | None = typer.Option(None, "--out", help="Directory for report.html and figures/ (default: RUN)."),
        csv: Path | None = typer.Option(None, "--csv", help="Also export the job rows to CSV."),
        parquet: Path | None = typer.Option(None, "--parquet", help="Also export the job rows to Parquet."),
    ) -> None:
        """Regenerate a run's self-contained HTML report (figures, tables, provenance) from its store."""
        from vbl_robust.campaigns import ResultStore, export
        from vbl_robust.report import build_report

        if out is not None and out.exists() and not out.is_dir():
            fail(f"--out {out}: is a file; the report goes into a directory (report.html and figures/)")
        try:
            path = build_report(run, out)
            if csv or parquet:
                with ResultStore.open_existing(run) as store:
                    for p in (csv, parquet):
                        if p is not None:
                            typer.echo(f"exported {export(store, p)}")
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        typer.echo(f"report: {path}")

    @app.command()
    def bundle(
        root: Path = typer.Argument(..., help="Directory of experiment run directories (the --out of reproduce "
                                    "paper|all)."),
        out: Path = typer.Option(..., "--out", help="Bundle directory (e.g. results/paper)."),
        reproduction: Path | None = typer.Option(None, "--reproduction", help="A Markdown file (REPRODUCTION.md) "
                                                 "whose part between '<!-- bundle:begin -->' and "
                                                 "'<!-- bundle:end -->' is replaced by the claims and status tables."),
        stores: bool = typer.Option(False, "--stores", help="Also a compact copy of each store (results.sqlite.xz), "
                                    "from which `reproduce --resume-from DIR` resumes an unfinished run elsewhere."),
    ) -> None:
        """Write a results bundle: per experiment the job table (Parquet), the report and the provenance, and a
        status table; runs still in progress are bundled as they stand (rerun to refresh)."""
        from vbl_robust.campaigns.bundle import write_bundle

        try:
            totals = write_bundle(root, out, reproduction=reproduction, stores=stores)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        for name, t in totals.items():
            typer.echo(f"{name}: {t['jobs_done']} of {t['jobs_planned']} jobs, {t['images_with_jobs']} images")
        typer.echo(f"bundle: {out}")
