"""A run described by a file: ``--config FILE`` (YAML) gives a command's options, and every run directory keeps
the full configuration it ran with as ``config.yaml``.

The file is a mapping of option names to values, as on the command line without the dashes (``max-evals: 400`` or
``max_evals: 400``; a repeatable option takes a list: ``perturb: [blur_px, "haze=0,0.3"]`` — quoted, as a comma
ends an item of a YAML list; a flag ``true`` or
``false``); an optional ``command:`` key names the command it is for. Options given on the command line override
the file: the file's values become the command's defaults (click's ``default_map``), so every value still goes
through the option's own conversion and checks (a bad value is refused naming the option). An unknown key, a
file that is not a mapping or a ``command:`` for another command is refused in one line before any work.

``config.yaml`` in a run directory holds every option of the invocation, the defaults included, in the same form:
``vbl-robust audit --config runs/audit/config.yaml`` repeats the run (it resumes into the same ``--out``; give
another ``--out`` to run it afresh). It is written when the command ends, if the run directory holds a store.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperCommand

from ..atomic import atomic_write

#: The file a run directory keeps its configuration in.
CONFIG_FILE = "config.yaml"
#: Options left out of the written configuration: how the output looks, not what ran.
_NOT_RECORDED = frozenset({"config", "quiet", "verbose"})
#: Most bytes a configuration file may have (a stated bound: a campaign file is a few hundred bytes).
MAX_CONFIG_BYTES = 1 << 20


def _key(name: str) -> str:
    return name.lstrip("-").replace("-", "_")


def read_config(path: Path, command: str, names: set[str]) -> dict[str, Any]:
    """The options of ``path`` for ``command`` (keys normalised to parameter names, all in ``names``);
    ``typer.BadParameter`` naming the file and the key for anything else."""
    import yaml

    try:
        if path.stat().st_size > MAX_CONFIG_BYTES:
            raise typer.BadParameter(f"{path}: larger than {MAX_CONFIG_BYTES} bytes", param_hint="--config")
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise typer.BadParameter(f"{path}: {exc.strerror or exc}", param_hint="--config") from None
    except yaml.YAMLError as exc:
        raise typer.BadParameter(f"{path}: not YAML ({str(exc).splitlines()[0]})", param_hint="--config") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise typer.BadParameter(f"{path}: expected a mapping of option names to values", param_hint="--config")
    data = dict(data)
    named = data.pop("command", command)
    if named != command:
        raise typer.BadParameter(f"{path}: a configuration for '{named}', not '{command}'", param_hint="--config")
    out = {}
    for key, value in data.items():
        name = _key(str(key))
        if name not in names or name in _NOT_RECORDED:
            raise typer.BadParameter(f"{path}: '{key}' is not an option of {command}", param_hint="--config")
        out[name] = [str(v) for v in value] if isinstance(value, list) else value
    return out


def apply_config(ctx: typer.Context, value: Path | None) -> Path | None:
    """Callback of the eager ``--config`` option: the file's values become the command's defaults."""
    if value is not None:
        names = {p.name for p in ctx.command.params if p.name}
        ctx.default_map = {**(ctx.default_map or {}), **read_config(Path(value), ctx.command.name or "", names)}
    return value


#: The ``--config FILE`` option (eager: the file is read before the other options are converted).
Config = Annotated[Path | None, typer.Option("--config", is_eager=True, callback=apply_config, help="Read the options "
                                             "from this YAML file (option: value; the command line overrides it); "
                                             "every run directory keeps its own as config.yaml.")]


def run_directory(command: str, params: dict[str, Any]) -> Path | None:
    """Where ``command`` wrote its run (its ``--out``; ``reproduce``'s default ``runs/<experiment>``)."""
    out = params.get("out")
    if out is None and command == "reproduce" and params.get("experiment"):
        out = Path("runs") / str(params["experiment"])
    return None if out is None else Path(out)


def write_config(command: str, params: dict[str, Any]) -> Path | None:
    """``config.yaml`` of a run: every option of the invocation (Paths as text), if its run directory holds a store
    (its own, or its experiments' for ``reproduce paper|all``); returns its path, or None."""
    import yaml

    where = run_directory(command, params)
    if where is None or not where.is_dir():
        return None
    if not ((where / "results.sqlite").exists() or any(where.glob("*/results.sqlite"))):
        return None

    def plain(v: Any) -> Any:
        if isinstance(v, Path):
            return str(v)
        if isinstance(v, list | tuple):
            return [plain(x) for x in v]
        return v

    body = {"command": command, **{k: plain(v) for k, v in sorted(params.items()) if k not in _NOT_RECORDED}}
    return atomic_write(where / CONFIG_FILE, yaml.safe_dump(body, sort_keys=False, allow_unicode=True))


class RecordingCommand(TyperCommand):
    """A campaign command: when it ends (done, failed or interrupted), its run directory gets ``config.yaml``."""

    def invoke(self, ctx: typer.Context) -> Any:
        try:
            return super().invoke(ctx)
        finally:
            try:
                write_config(ctx.command.name or "", dict(ctx.params))
            except OSError as exc:  # a full disk must not hide the command's own outcome, but is said
                logging.getLogger(__name__).warning("%s not written: %s", CONFIG_FILE, exc)
