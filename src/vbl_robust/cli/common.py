"""Helpers shared by the CLI commands: turning user input into one-line errors."""

from __future__ import annotations

import typer


def fail(message: str, code: int = 2) -> None:
    """Print a one-line error and exit (user mistakes never show a traceback)."""
    typer.secho(f"error: {message}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def parse_range(text: str, *, name: str, symmetric: bool = False) -> tuple[float, float]:
    """Parse ``"15"`` (→ ±15 when ``symmetric``) or ``"0.7,1.4"`` into ``(lower, upper)``."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise typer.BadParameter(f"{name}: expected a number or 'lower,upper', got {text!r}") from None
    if len(vals) == 1 and symmetric:
        a = abs(vals[0])
        return (-a, a)
    if len(vals) != 2:
        raise typer.BadParameter(f"{name}: expected 'lower,upper', got {text!r}")
    return (vals[0], vals[1])
