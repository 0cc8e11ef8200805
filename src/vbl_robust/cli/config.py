"""A run described by a file: ``--config FILE`` (YAML) gives a command's options, and every run directory keeps
the full configuration it ran with as ``config.yaml``.

The file is a mapping of option names to values, as on the command line without the dashes (``max-evals: 400`` or
``max_evals: 400``, ``detector: twostage``, ``images: 50``; the parameter names, e.g. ``design`` or ``n``, are
accepted as aliases); a repeatable option takes a list: ``perturb: [blur_px, "haze=0,0.3"]`` — quoted, as a comma
ends an item of a YAML list; a flag ``true`` or ``false``); an optional ``command:`` key names the command it is
for. Options given on the command line override the file: the file's values become the command's defaults (click's
``default_map``), so every value still goes through the option's own conversion and checks (a bad value is refused
naming the option).

Refused in one line before any work: a file that is not a regular file (``/dev/zero``, a FIFO), larger than
:data:`MAX_CONFIG_BYTES` or expanding past it through YAML aliases (an alias bomb is refused after reading its
nodes once: each node's expanded size is computed once), not UTF-8, not YAML, not a mapping; an unknown key, a key
given twice (or under two names of one option), a ``command:`` for another command; a boolean where a number, a
path or a text is meant (``seed: true``), a fraction where an integer is meant, a list for a one-value option.
Only YAML's safe constructors run (no ``!!python`` tag is honoured).

``config.yaml`` in a run directory holds every option of the invocation, the defaults included, in the same form
(keys as the options are spelt): ``vbl-robust audit --config runs/audit/config.yaml`` repeats the run (it resumes
into the same ``--out``; give another ``--out`` to run it afresh). It is written when the run starts — once its
store has accepted the campaign (:func:`record_configuration`) — never by a command that was refused, so a refused
command leaves the run directory as it was. The run's provenance in its store (``config["user"]`` of each run) holds
the same parameters (:func:`run_config`), with what the run resolved from them (the images counted, the methods
parsed) in place of what was typed.
"""

from __future__ import annotations

import logging
import os
import stat
from collections.abc import Iterable
from contextvars import ContextVar
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any, get_args, get_origin

import typer
from typer._click.globals import get_current_context  # typer's own click: where its commands run
from typer.core import TyperCommand

from ..atomic import atomic_write

#: The file a run directory keeps its configuration in.
CONFIG_FILE = "config.yaml"
#: Options left out of the written configuration: how the output looks, not what ran.
_NOT_RECORDED = frozenset({"config", "quiet", "verbose"})
#: Most bytes a configuration file may have, and most its values may expand to through YAML aliases (a stated
#: bound: a campaign file is a few hundred bytes).
MAX_CONFIG_BYTES = 1 << 20
#: ``ctx.meta`` key: this invocation's ``config.yaml`` is written (once per command).
_RECORDED = "vbl_config_recorded"
#: The campaign command running now (its context), for :func:`record_configuration`.
_RUNNING: ContextVar[Any] = ContextVar("vbl_running_campaign", default=None)


class ConfigError(ValueError):
    """A configuration file refused (one line, without the file's name)."""


def _key(name: str) -> str:
    return name.lstrip("-").replace("-", "_")


def option_key(param: Any) -> str:
    """The key of ``param`` in a configuration file as the option is spelt (``--detector`` → ``detector``,
    ``--max-evals`` → ``max_evals``); an argument's, its name."""
    return next((_key(o) for o in param.opts if o.startswith("--")), param.name or "")


def _keys(params: Iterable[Any]) -> dict[str, Any]:
    """Every key a file may give for each parameter: each long option as spelt, and the parameter's name."""
    out: dict[str, Any] = {}
    params = [p for p in params if p.name and p.name not in _NOT_RECORDED]
    for p in params:  # the option's spellings first: they win over another parameter's name
        for o in p.opts:
            if o.startswith("--"):
                out.setdefault(_key(o), p)
    for p in params:
        out.setdefault(p.name or "", p)
    return out


def _strict_loader() -> type:
    """A YAML safe loader (libyaml's when installed) that refuses a mapping's key given twice."""
    import yaml  # not for ``--help``

    base = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

    class StrictLoader(base):  # type: ignore[misc, valid-type]
        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            if isinstance(node, yaml.MappingNode):
                seen: set[Any] = set()
                for key_node, _ in node.value:
                    if key_node.tag == "tag:yaml.org,2002:merge":
                        continue
                    key = self.construct_object(key_node, deep=True)
                    try:
                        twice = key in seen
                    except TypeError:  # an unhashable key: the safe constructor refuses it itself
                        continue
                    if twice:
                        raise ConfigError(f"line {key_node.start_mark.line + 1}: key {key!r} given twice")
                    seen.add(key)
            return super().construct_mapping(node, deep=deep)

    return StrictLoader


def expanded_size(root: Any, limit: int) -> int:
    """The size of the YAML node graph ``root`` with every alias expanded (a scalar counts its characters + 1, a
    collection 1 + its items; at most ``limit`` + 1: counting stops there), each node's size computed once — so an
    alias bomb is measured in the time it takes to read its few nodes. ``ConfigError`` for a recursive alias."""
    import yaml  # not for ``--help``

    def items(node: Any) -> list[Any]:
        if isinstance(node, yaml.SequenceNode):
            return list(node.value)
        if isinstance(node, yaml.MappingNode):
            return [n for pair in node.value for n in pair]
        return []

    size: dict[int, int] = {}
    open_: set[int] = set()  # nodes being expanded (their items not all sized yet)
    stack: list[tuple[Any, bool]] = [(root, False)]
    while stack:
        node, ready = stack.pop()
        if ready:
            own = len(node.value) + 1 if isinstance(node, yaml.ScalarNode) else 1
            size[id(node)] = min(limit + 1, own + sum(size[id(n)] for n in items(node)))
            open_.discard(id(node))
            continue
        if id(node) in size:
            continue
        if id(node) in open_:
            raise ConfigError(f"line {node.start_mark.line + 1}: a recursive alias (a value that contains itself)")
        open_.add(id(node))
        stack.append((node, True))
        stack.extend((n, False) for n in items(node) if id(n) not in size)
    return size[id(root)]


def load_yaml(path: Path) -> Any:
    """The YAML document of the configuration file ``path``, read within bounds (module docstring);
    ``ConfigError`` (one line, without the path) for anything refused, ``OSError`` when it cannot be read."""
    import yaml  # not for ``--help``

    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise ConfigError("not a regular file")
    with open(path, "rb") as f:
        raw = f.read(MAX_CONFIG_BYTES + 1)
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"larger than {MAX_CONFIG_BYTES} bytes")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ConfigError(f"not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line})") from None
    loader = _strict_loader()(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        if expanded_size(node, MAX_CONFIG_BYTES) > MAX_CONFIG_BYTES:
            raise ConfigError(f"its values expand past {MAX_CONFIG_BYTES} bytes through YAML aliases")
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise ConfigError(f"not YAML ({' '.join(str(exc).split())})") from None
    except ConfigError:
        raise
    except ValueError as exc:  # a value YAML reads but Python will not hold (an integer of 5000 digits)
        raise ConfigError(f"a value it cannot read ({' '.join(str(exc).split())[:120]})") from None
    except RecursionError:
        raise ConfigError("not YAML (nested too deeply)") from None
    finally:
        loader.dispose()


class ValueKind(StrEnum):
    """What a value of an option is (a text: a path, a choice, a string); its value words the error message."""

    FLAG = "flag"
    INTEGER = "an integer"
    NUMBER = "a number"
    TEXT = "a value"


def _kind(param: Any) -> ValueKind:
    """What a value of ``param`` is."""
    if getattr(param, "is_flag", False):
        return ValueKind.FLAG
    annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)  # typer's parameters
    if get_origin(annotation) is list:
        annotation = (get_args(annotation) or (str,))[0]
    name = getattr(getattr(param, "type", None), "name", None)  # click's
    if annotation is bool or name == "boolean":
        return ValueKind.FLAG
    if annotation is int or name == "integer":
        return ValueKind.INTEGER
    if annotation is float or name == "float":
        return ValueKind.NUMBER
    return ValueKind.TEXT


def _value(key: str, value: Any, param: Any) -> Any:
    """``value`` of ``key`` for ``param`` as a default (a list of texts for a repeatable option), or
    ``ConfigError`` for a value of the wrong kind that the option's own conversion would take silently."""
    kind = _kind(param)
    if value is None:
        return None
    if isinstance(value, dict):
        raise ConfigError(f"'{key}': expected one value, got a mapping")
    if getattr(param, "multiple", False) or param.nargs != 1:
        values = value if isinstance(value, list) else [value]
        for v in values:
            _scalar(key, v, kind)
        return [str(v) for v in values]
    if isinstance(value, list):
        raise ConfigError(f"'{key}': expected one value, got a list")
    return _scalar(key, value, kind)


def _scalar(key: str, value: Any, kind: ValueKind) -> Any:
    if isinstance(value, list | dict):
        raise ConfigError(f"'{key}': expected one value per item, got {type(value).__name__}")
    if kind == ValueKind.FLAG:
        if not isinstance(value, bool):
            raise ConfigError(f"'{key}': a flag takes true or false, got {value!r}")
        return value
    if isinstance(value, bool):
        raise ConfigError(f"'{key}': expected {kind.value}, got the boolean {str(value).lower()}")
    if kind == ValueKind.INTEGER and isinstance(value, float) and not value.is_integer():
        raise ConfigError(f"'{key}': expected an integer, got {value!r}")
    return value


def read_config(path: Path, command: str, params: Iterable[Any]) -> dict[str, Any]:
    """The options of ``path`` for ``command`` (keys as the options are spelt or the parameters' names; the result
    keyed by parameter name), ``typer.BadParameter`` naming the file and the key for anything else."""
    keys = _keys(params)
    try:
        data = load_yaml(path)
    except OSError as exc:
        raise typer.BadParameter(f"{path}: {exc.strerror or exc}", param_hint="--config") from None
    except ConfigError as exc:
        raise typer.BadParameter(f"{path}: {exc}", param_hint="--config") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise typer.BadParameter(f"{path}: expected a mapping of option names to values", param_hint="--config")
    data = dict(data)
    named = data.pop("command", command)
    if named != command:
        raise typer.BadParameter(f"{path}: a configuration for '{named}', not '{command}'", param_hint="--config")
    out: dict[str, Any] = {}
    given: dict[str, str] = {}
    for key, value in data.items():
        param = keys.get(_key(str(key)))
        if param is None or not param.name:
            raise typer.BadParameter(f"{path}: '{key}' is not an option of {command}", param_hint="--config")
        if param.name in given:
            raise typer.BadParameter(f"{path}: '{given[param.name]}' and '{key}' name the same option "
                                     f"({option_key(param)}); give it once", param_hint="--config")
        given[param.name] = str(key)
        try:
            out[param.name] = _value(str(key), value, param)
        except ConfigError as exc:
            raise typer.BadParameter(f"{path}: {exc}", param_hint="--config") from None
    return out


def apply_config(ctx: typer.Context, value: Path | None) -> Path | None:
    """Callback of the eager ``--config`` option: the file's values become the command's defaults."""
    if value is not None:
        ctx.default_map = {**(ctx.default_map or {}),
                           **read_config(Path(value), ctx.command.name or "", ctx.command.params)}
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


def write_config(command: str, params: dict[str, Any], keys: dict[str, str] | None = None) -> Path | None:
    """``config.yaml`` of a run: every option of the invocation (Paths as text; ``keys``: parameter name → key as
    the option is spelt), if its run directory holds a store (its own, or its experiments' for ``reproduce
    paper|all``); returns its path, or None."""
    where = run_directory(command, params)
    if where is None or not where.is_dir():
        return None
    if not ((where / "results.sqlite").exists() or any(where.glob("*/results.sqlite"))):
        return None
    import yaml  # not for ``--help``

    body = recorded(command, params, keys)
    return atomic_write(where / CONFIG_FILE, yaml.safe_dump(body, sort_keys=False, allow_unicode=True))


def _plain(v: Any) -> Any:
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    return v


def recorded(command: str, params: dict[str, Any], keys: dict[str, str] | None = None) -> dict[str, Any]:
    """What ``config.yaml`` holds of ``command``'s ``params``: ``command`` first, then every option but
    :data:`_NOT_RECORDED` (keys as the options are spelt: ``keys``, parameter name → key; Paths as text)."""
    keys = keys or {}
    return {"command": command, **{keys.get(k, k): _plain(v) for k, v in sorted(params.items())
                                   if k not in _NOT_RECORDED}}


def parameters() -> dict[str, Any]:
    """The running command's parameters (parameter name → the value it runs with), as typer parsed them; empty
    outside a command."""
    ctx = get_current_context(silent=True)
    return dict(ctx.params) if ctx is not None else {}


def run_config(command: str, **resolved: Any) -> dict[str, Any]:
    """A run's configuration as its provenance keeps it: the running command's parameters as ``config.yaml``
    records them (:func:`recorded`), with what the run resolved from them in place of what was typed
    (``resolved``: the images counted, the methods parsed, …)."""
    ctx = get_current_context(silent=True)
    params = dict(ctx.params) if ctx is not None else {}
    keys = {p.name: option_key(p) for p in ctx.command.params if p.name} if ctx is not None else {}
    return {**recorded(command, params, keys), **resolved}


def record_configuration() -> Path | None:
    """Write the running campaign command's ``config.yaml`` (once per invocation): called when its run has started
    — its store accepted the campaign — so a refused command never rewrites it. A file that cannot be written is
    said (a full disk must not stop the run) and the run goes on; outside a campaign command it does nothing."""
    ctx = _RUNNING.get()
    if ctx is None or ctx.meta.get(_RECORDED):
        return None
    ctx.meta[_RECORDED] = True
    keys = {p.name: option_key(p) for p in ctx.command.params if p.name}
    try:
        return write_config(ctx.command.name or "", dict(ctx.params), keys)
    except OSError as exc:
        logging.getLogger(__name__).warning("%s not written: %s", CONFIG_FILE, exc)
        return None


class RecordingCommand(TyperCommand):
    """A campaign command: once its run starts (:func:`record_configuration`, called by the CLI's runner), its run
    directory gets ``config.yaml``."""

    def invoke(self, ctx: typer.Context) -> Any:
        token = _RUNNING.set(ctx)
        try:
            return super().invoke(ctx)
        finally:
            _RUNNING.reset(token)
