"""``vbl-robust scenes``: write a synthetic LARD-V2-format dataset (single images, or approach sequences)."""

from __future__ import annotations

from pathlib import Path

import typer

from ..constants import MAX_IMAGES
from .common import fail


def register(app: typer.Typer) -> None:
    @app.command()
    def scenes(
        n: int = typer.Option(100, "--n", min=1, max=MAX_IMAGES, help="Number of approach images (without --sequences)."),
        seed: int = typer.Option(0, "--seed", min=0, help="Seed; the same seed gives the same dataset."),
        out: Path = typer.Option(..., "--out", help="Output directory (images/, metadata CSV, runway DB JSON)."),
        width: int = typer.Option(1024, help="Image width in pixels."),
        height: int = typer.Option(1024, help="Image height in pixels."),
        fov: float = typer.Option(60.0, "--fov", help="Horizontal field of view in degrees."),
        envelopes: str = typer.Option("far,medium,close", help="Comma-separated LARD V2 envelopes to sample "
                                      "(single images only)."),
        sequences: int | None = typer.Option(None, "--sequences", min=1, help="Write this many approach sequences "
                                             "(one airport each) instead of single images; CSV columns sequence_id, "
                                             "frame_index, time_s."),
        frames: int = typer.Option(20, "--frames", min=1, help="Frames per sequence."),
        rate: float = typer.Option(10.0, "--rate", help="Frame rate of a sequence, Hz."),
        speed: float = typer.Option(70.0, "--speed", help="Ground speed along the glide path, m/s (20 frames at "
                                    "10 Hz fly 133 m; 80 frames at 1 Hz fly most of the far → close approach)."),
    ) -> None:
        """Generate approach scenes with exact ground truth, written in LARD V2 format."""
        from vbl_robust import scenes as sc

        try:
            if sequences is not None:
                csv_path = sc.write_sequences(out, sequences, frames, rate, seed=seed, width=width, height=height,
                                              fov_deg=fov, ground_speed_mps=speed)
            else:
                envs = tuple(e.strip() for e in envelopes.split(",") if e.strip())
                csv_path = sc.write_dataset(out, n, seed=seed, width=width, height=height, fov_deg=fov,
                                            envelopes=envs)
        except (ValueError, FileNotFoundError, RuntimeError) as exc:
            fail(str(exc))
        what = f"{sequences} sequences of {frames} frames at {rate:g} Hz" if sequences is not None else f"{n} scenes"
        typer.echo(f"wrote {what}: {csv_path}")
