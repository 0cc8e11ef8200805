"""The ``vbl-robust`` command line (typer). Each command is a module-level function of a module of this package
(its options: :mod:`.options` for those several commands share, its own module for the rest), registered below in
one line.

Heavy imports (torch, ultralytics, OpenCV) happen inside the commands, so ``vbl-robust --help`` is instant.
"""

from __future__ import annotations

import errno
import sqlite3
import warnings
from typing import Annotated

import typer
from typer.core import TyperGroup

from vbl_robust.constants import TORCH_JIT_WARNING

from . import audit, check, report, reproduce, risk, scenes, train, truth, verify, zones
from .common import set_verbosity, stop_on_sigterm
from .config import RecordingCommand
from .options import Quiet, Verbose, variant

#: The commands that run a campaign into a store (a rerun resumes them).
_CAMPAIGNS = frozenset({"audit", "demo", "risk", "reproduce", "truth"})


class _Commands(TyperGroup):
    """The command group: refuses an empty argument before any command runs. ``--out ""`` would otherwise become
    ``Path("")`` = the current directory (typer converts before any check could see it), and no option or argument
    of this CLI means anything when empty."""

    def parse_args(self, ctx: typer.Context, args: list[str]) -> list[str]:
        for i, arg in enumerate(args):
            name, eq, value = arg.partition("=")
            if arg == "" or (eq and name.startswith("--") and value == ""):
                option = name if eq else (args[i - 1] if i and args[i - 1].startswith("-") else "an argument")
                raise typer.BadParameter("an empty value (name a file or directory, or leave the option out)",
                                         param_hint=option)
            try:  # bytes that are not UTF-8 reach Python as surrogates: no store, report or config can hold them
                arg.encode("utf-8")
            except UnicodeEncodeError:
                option = args[i - 1] if i and args[i - 1].startswith("-") and not eq else (name if eq else "an argument")
                raise typer.BadParameter(f"{arg.encode('utf-8', 'backslashreplace').decode()!r} is not valid UTF-8 "
                                         "(rename it: the stores, reports and config.yaml hold names as UTF-8)",
                                         param_hint=option) from None
        # the command's name: the first argument that is not an option (the group's own options are flags)
        ctx.meta["vbl_command"] = next((a for a in args if not a.startswith("-")), None)
        return super().parse_args(ctx, args)

    def invoke(self, ctx: typer.Context) -> object:
        """Run the command; an operating-system or SQLite error that no command handles (a full disk, a store or
        report directory without write permission, …) ends it in one line naming the file, exit 1; in a campaign
        every job committed before stays in the store, and a rerun resumes once the cause is fixed."""
        resumable = ctx.meta.get("vbl_command") in _CAMPAIGNS
        kept = " (jobs stored before it are kept: fix the cause and rerun to resume)" if resumable else ""
        try:
            return super().invoke(ctx)
        except OSError as exc:
            if exc.errno == errno.EPIPE:  # a closed pipe (| head): typer's own handling
                raise
            where = f": {exc.filename}" if exc.filename else ""
            typer.echo(f"error: {exc.strerror or exc}{where}{kept}", err=True)
        except sqlite3.Error as exc:
            typer.echo(f"error: the results store: {exc}{kept}", err=True)
        raise typer.Exit(1)


app = typer.Typer(
    cls=_Commands,
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
        from importlib.metadata import version  # 0.1 s: for --version only, not for ``--help``

        typer.echo(f"vbl-robust {version('vbl-robust')}")
        raise typer.Exit()


#: ``-v`` / ``-q`` before the command (they apply to the whole invocation)
_Verbose = variant(Verbose, help="Log progress details (INFO); also after the command.")
_Quiet = variant(Quiet, help="No progress bars or tables; also after the command.")


@app.callback()
def _main(
    verbose: _Verbose = False, quiet: _Quiet = False,
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and "
                                          "exit.")] = False,
) -> None:
    set_verbosity(quiet=quiet, verbose=verbose, before_command=True)
    warnings.filterwarnings("ignore", message=TORCH_JIT_WARNING, category=FutureWarning)


#: The commands, in the order ``vbl-robust --help`` lists them.
COMMANDS = (scenes.scenes, check.check, audit.audit, audit.demo, risk.risk, reproduce.reproduce, truth.truth,
            report.report, report.bundle, report.merge, train.train, train.ship, train.harden, zones.zones,
            verify.verify)
for _command in COMMANDS:  # a campaign's run directory keeps its configuration (config.yaml)
    app.command(cls=RecordingCommand if _command.__name__ in _CAMPAIGNS else None)(_command)


def main() -> None:  # pragma: no cover - console entry
    stop_on_sigterm()
    app()
