"""Helpers shared by the CLI commands: one-line errors, verbosity (the shared options: :mod:`.options`)."""

from __future__ import annotations

import logging
import math

import typer

#: what the options before the command said (``vbl-robust -q audit …``)
_GLOBAL = {"quiet": False, "verbose": False}


def stop_on_sigterm() -> None:
    """Make SIGTERM (``kill PID``, a scheduler's or a session's stop) end the command as Ctrl-C does: a campaign
    records its run as interrupted with its wall time, its finished jobs stay, and the command exits with one line.
    A second SIGTERM kills at once (the default action is restored by the first)."""
    import signal

    def _interrupt(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _interrupt)


def set_verbosity(*, quiet: bool = False, verbose: bool = False, before_command: bool = False) -> bool:
    """Apply ``-v`` (INFO logging) and ``-q`` given before the command (``before_command``: what they say for this
    invocation) or after it (added to that); returns whether to be quiet."""
    if before_command:
        _GLOBAL.update(quiet=quiet, verbose=verbose)
    _GLOBAL["quiet"] = _GLOBAL["quiet"] or quiet
    _GLOBAL["verbose"] = _GLOBAL["verbose"] or verbose
    logging.basicConfig(format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(logging.INFO if _GLOBAL["verbose"] else logging.WARNING)
    return _GLOBAL["quiet"]


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
    if not all(math.isfinite(v) for v in vals):
        raise typer.BadParameter(f"{name}: expected finite numbers, got {text!r}")
    if len(vals) == 1 and symmetric:
        if vals[0] <= 0:  # "-5" would silently mean ±5
            raise typer.BadParameter(f"{name} {text}: a half-width must be > 0 (or give 'lower,upper')")
        return (-vals[0], vals[0])
    if len(vals) != 2:
        raise typer.BadParameter(f"{name}: expected 'lower,upper', got {text!r}")
    if not vals[0] < vals[1]:
        raise typer.BadParameter(f"{name} {text}: expected lower < upper")
    return (vals[0], vals[1])


def parse_lipschitz(text: str | None) -> float | tuple[float, ...] | None:
    """``--lipschitz``: one number, or one per parameter (checked against the box where the box is known)."""
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        vals = ()
    if not vals or any(not math.isfinite(v) or v < 0 for v in vals):
        fail(f"--lipschitz {text}: expected a finite number >= 0, or one per parameter")
    return vals[0] if len(vals) == 1 else vals
