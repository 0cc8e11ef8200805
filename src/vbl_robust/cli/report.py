"""``vbl-robust report RUN``: rebuild the HTML report (and exports) of a run directory from its results store."""

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
