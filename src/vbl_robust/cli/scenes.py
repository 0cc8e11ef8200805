"""``vbl-robust scenes``: write a synthetic LARD-V2-format dataset."""

from __future__ import annotations

from pathlib import Path

import typer

from .common import fail


def register(app: typer.Typer) -> None:
    @app.command()
    def scenes(
        n: int = typer.Option(100, "--n", min=1, help="Number of approach images."),
        seed: int = typer.Option(0, "--seed", help="Seed; the same seed gives the same dataset."),
        out: Path = typer.Option(..., "--out", help="Output directory (images/, metadata CSV, runway DB JSON)."),
        width: int = typer.Option(1024, help="Image width in pixels."),
        height: int = typer.Option(1024, help="Image height in pixels."),
        fov: float = typer.Option(60.0, "--fov", help="Horizontal field of view in degrees."),
        envelopes: str = typer.Option("far,medium,close", help="Comma-separated LARD V2 envelopes to sample."),
    ) -> None:
        """Generate approach scenes with exact ground truth, written in LARD V2 format."""
        from vbl_robust import scenes as sc

        envs = tuple(e.strip() for e in envelopes.split(",") if e.strip())
        try:
            csv_path = sc.write_dataset(out, n, seed=seed, width=width, height=height, fov_deg=fov, envelopes=envs)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        typer.echo(f"wrote {n} scenes: {csv_path}")
