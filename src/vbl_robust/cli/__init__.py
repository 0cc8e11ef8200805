"""The ``vbl-robust`` command line (typer). Each sub-command lives in its own module of this package.

Heavy imports (torch, ultralytics, OpenCV) happen inside the commands, so ``vbl-robust --help`` is instant.
"""

from __future__ import annotations

import importlib
import warnings

import typer

from .common import set_verbosity, stop_on_sigterm

app = typer.Typer(
    name="vbl-robust",
    help="Find the perturbations (camera roll, contrast, …) that make a vision-based landing pipeline fail.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: flags read "-q, --quiet" (rich mode shows "<bool>"), long help wraps wide
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        typer.echo(f"vbl-robust {version('vbl-robust')}")
        raise typer.Exit()

# Sub-command modules; each defines `register(app)`. A module that is not there yet is skipped.
_COMMAND_MODULES = ("scenes", "audit", "risk", "reproduce", "truth", "report", "train", "zones")


@app.callback()
def _main(verbose: bool = typer.Option(False, "--verbose", "-v", help="Log progress details (INFO); also after the command."),
          quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars or tables; also after the command."),
          version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                               help="Print the version and exit.")) -> None:
    set_verbosity(quiet=quiet, verbose=verbose, before_command=True)
    from vbl_robust.constants import TORCH_JIT_WARNING

    warnings.filterwarnings("ignore", message=TORCH_JIT_WARNING, category=FutureWarning)


for _name in _COMMAND_MODULES:
    try:
        _mod = importlib.import_module(f"{__name__}.{_name}")
    except ModuleNotFoundError as exc:  # command not written yet
        if exc.name != f"{__name__}.{_name}":
            raise
        continue
    _mod.register(app)


def main() -> None:  # pragma: no cover - console entry
    stop_on_sigterm()
    app()
