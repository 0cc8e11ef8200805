"""``vbl-robust scenes``: write a synthetic LARD-V2-format dataset (single images, or approach sequences)."""

from __future__ import annotations

from typing import Annotated

import typer

from ..constants import MAX_IMAGE_SIDE, MAX_IMAGES
from . import options as o
from .common import fail, one_line

N = Annotated[int, typer.Option("--n", min=1, max=MAX_IMAGES, help="Number of approach images (without --sequences).")]
Seed = o.variant(o.Seed, max=None, help="Seed; the same seed gives the same dataset.")
Out = o.variant(o.Out, help="Output directory (images/, metadata CSV, runway DB JSON).")
Width = o.variant(o.Width, help=f"Image width in pixels (16 to {MAX_IMAGE_SIDE}).")
Height = o.variant(o.Height, help=f"Image height in pixels (16 to {MAX_IMAGE_SIDE}).")
Fov = Annotated[float, typer.Option("--fov", help="Horizontal field of view in degrees.")]
Envelopes = Annotated[str, typer.Option(help="Comma-separated LARD V2 envelopes to sample (single images only).")]
Sequences = Annotated[int | None, typer.Option("--sequences", min=1, help="Write this many approach sequences (one "
                                               "airport each) instead of single images; CSV columns sequence_id, "
                                               "frame_index, time_s.")]
Frames = o.variant(o.Frames, int, help="Frames per sequence.")
Rate = o.variant(o.Rate, float, help="Frame rate of a sequence, Hz.")
Speed = Annotated[float, typer.Option("--speed", help="Ground speed along the glide path, m/s (20 frames at 10 Hz fly "
                                      "133 m; 80 frames at 1 Hz fly most of the far → close approach).")]


def scenes(
    n: N = 100, seed: Seed = 0, out: Out = ...,  # ``...``: required (typer), in its place in the help
    width: Width = 1024, height: Height = 1024, fov: Fov = 60.0, envelopes: Envelopes = "far,medium,close",
    sequences: Sequences = None, frames: Frames = 20, rate: Rate = 10.0, speed: Speed = 70.0,
) -> None:
    """Generate approach scenes with exact ground truth, written in LARD V2 format."""
    from vbl_robust.scenes.export import write_dataset
    from vbl_robust.scenes.sequences import write_sequences

    if out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file, not a directory")
    if out.is_dir() and (held := sorted(p.name for p in out.iterdir())):
        fail(f"--out {out}: not empty (holds {', '.join(held[:3])}{', …' if len(held) > 3 else ''}): a dataset is "
             "written into a new or empty directory, never over another")
    with one_line(ValueError, FileNotFoundError, RuntimeError):
        if sequences is not None:
            csv_path = write_sequences(out, sequences, frames, rate, seed=seed, width=width, height=height,
                                       fov_deg=fov, ground_speed_mps=speed)
        else:
            envs = tuple(e.strip() for e in envelopes.split(",") if e.strip())
            csv_path = write_dataset(out, n, seed=seed, width=width, height=height, fov_deg=fov, envelopes=envs)
    what = f"{sequences} sequences of {frames} frames at {rate:g} Hz" if sequences is not None else f"{n} scenes"
    typer.echo(f"wrote {what}: {csv_path}")
