"""MkDocs hook: the CLI reference page, generated from the typer app at build time.

``docs/reference/cli.md`` holds two markers: ``<!-- cli-commands -->`` becomes a table of every command of
``vbl_robust.cli.app`` (its whole summary, linked to its section); ``<!-- cli-reference -->`` the global options
and one section per command (anchor ``vbl-robust-NAME``): its help, its usage line, and tables of its arguments
and options — name, type, default, help — read from the click command objects typer builds
(``typer.main.get_command``), not from ``--help`` text. Each option has an anchor of its own, ``NAME-OPTION`` (``#audit-max-evals``). A command or
option added to the CLI appears here without editing the page.
"""

from __future__ import annotations

import re
from typing import Any

import typer

MARKER = "<!-- cli-reference -->"
COMMANDS_MARKER = "<!-- cli-commands -->"
#: an int bound this large is no bound a reader needs to see (typer's default for an unbounded ``min=``)
_NO_BOUND = 2**62


def _inline(text: str) -> str:
    """``text`` as one line of Markdown inside a table cell: code spans kept, everything else escaped (``<``,
    ``|``, emphasis characters), so a help string renders as written."""
    parts = re.split(r"(`[^`]*`)", " ".join(text.split()))
    out = []
    for i, part in enumerate(parts):
        if i % 2:  # a code span: only the pipe needs escaping inside a table
            out.append(part.replace("|", "\\|"))
            continue
        part = part.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
        out.append(re.sub(r"([\\|*_\[\]])", r"\\\1", part))
    return "".join(out)


def _code(text: str) -> str:
    return "`" + text.replace("|", "\\|") + "`"


def _number(x: float | int) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def _type(param: Any, ctx: Any) -> str:
    """The value a parameter takes: ``flag``, ``int ≥ 0``, ``float 0–1``, ``path``, ``str, repeatable``, …"""
    if getattr(param, "is_flag", False):
        return "flag"
    label = param.display_type(ctx).strip("<>")
    if label.startswith("list[") and label.endswith("]"):
        label = label[5:-1]
    label = label.removesuffix(" range").lower()
    lo, hi = getattr(param, "min", None), getattr(param, "max", None)
    hi = None if hi is not None and hi >= _NO_BOUND else hi
    lo = None if lo is not None and lo <= -_NO_BOUND else lo
    if lo is not None and hi is not None:
        label += f" {_number(lo)}–{_number(hi)}"
    elif lo is not None:
        label += f" ≥ {_number(lo)}"
    elif hi is not None:
        label += f" ≤ {_number(hi)}"
    if getattr(param, "multiple", False):
        label += ", repeatable"
    elif getattr(param, "nargs", 1) == -1:
        label += ", one or more"
    return _inline(label)


def _default(param: Any, ctx: Any) -> str:
    """The default as the command applies it; ``–`` where there is none (the help says what happens then)."""
    if getattr(param, "required", False):
        return "required"
    value = param.get_default(ctx, call=False)
    if value is None:
        return "–"
    if getattr(param, "is_flag", False):
        if param.secondary_opts:
            return _code(param.opts[0] if value else param.secondary_opts[0])
        return "on" if value else "off"
    if value == () or value == []:
        return "–"
    if callable(value):
        return "(computed)"
    if isinstance(value, (list, tuple)):
        return ", ".join(_code(str(v)) for v in value)
    return _code(str(getattr(value, "value", value)))


def _nowrap(cell: str) -> str:
    """A short default on one line (``--no-landscape``); a long one (a list of methods) may wrap at its commas."""
    return f'<span class="cli-default">{cell}</span>' if len(cell) <= 20 else cell


def _option_name(param: Any) -> str:
    names = " ".join(_code(o) for o in sorted(param.opts, key=lambda o: not o.startswith("--")))
    if param.secondary_opts:
        names += " / " + " ".join(_code(o) for o in param.secondary_opts)
    return names


def _anchor(command: str, param: Any) -> str:
    long = next((o for o in param.opts if o.startswith("--")), param.opts[0])
    return f"{command or 'global'}-{long.lstrip('-')}"


def _argument(param: Any) -> str:
    name = param.name.upper() + ("..." if param.nargs == -1 else "")
    return name if param.required else f"[{name}]"


def _usage(path: str, command: Any) -> str:
    """``Usage: vbl-robust NAME [OPTIONS] RUN``: the arguments by the names the docs use (RUN, DATA, SOURCES...)."""
    arguments = [_argument(p) for p in command.params if p.param_type_name == "argument"]
    tail = " COMMAND [ARGS]..." if hasattr(command, "list_commands") else ""
    return " ".join([f"Usage: {path} [OPTIONS]", *arguments]) + tail


def _tables(name: str, command: Any, ctx: Any) -> list[str]:
    arguments = [p for p in command.params if p.param_type_name == "argument"]
    options = [p for p in command.params if p.param_type_name == "option" and not getattr(p, "hidden", False)]
    lines: list[str] = []
    if arguments:
        lines += ["**Arguments**", "", "| argument | type | what it is |", "|---|---|---|"]
        for p in arguments:
            lines.append(f"| {_code(_argument(p))} | {_type(p, ctx)} | {_inline(getattr(p, 'help', None) or '')} |")
        lines.append("")
    lines += ["**Options**", "", "| option | type | default | what it does |", "|---|---|---|---|"]
    for p in options:
        anchor = _anchor(name, p)
        lines.append(f'| <span class="cli-name" id="{anchor}">[{_option_name(p)}](#{anchor})</span> | {_type(p, ctx)} '
                     f"| {_nowrap(_default(p, ctx))} | {_inline(p.help or '')} |")
    lines += ['| <span class="cli-name">`-h` `--help`</span> | flag | off | Show the help and exit. |', ""]
    return lines


def _commands() -> tuple[Any, Any, dict[str, Any]]:
    from vbl_robust.cli import app

    group = typer.main.get_command(app)
    root = group.context_class(group, info_name="vbl-robust")
    return group, root, {name: group.get_command(root, name) for name in group.list_commands(root)}


def command_table() -> str:
    """The navigation: every command, linked to its section, with its whole summary."""
    parts = ["| command | what it does |", "|---|---|"]
    for name, command in _commands()[2].items():
        parts.append(f"| [`{name}`](#vbl-robust-{name}) | {_inline(command.help or '')} |")
    return "\n".join(parts)


def cli_reference() -> str:
    """Markdown for every command of the ``vbl-robust`` app: a table of the commands, the global options, then
    one section per command in the CLI's own order."""
    group, root, commands = _commands()
    parts = ["## vbl-robust", "", _inline(group.help or ""), "", "```text", _usage("vbl-robust", group), "```", "",
              "`-q` and `-v` work before or after the command: `vbl-robust -q audit` is `vbl-robust audit -q`.",
              ""]
    parts += _tables("", group, root)
    for name, command in commands.items():
        ctx = command.context_class(command, info_name=name, parent=root)
        parts += [f"## vbl-robust {name}", "", _inline(command.help or ""), "", "```text", _usage(f"vbl-robust {name}", command),
                  "```", ""]
        parts += _tables(name, command, ctx)
    return "\n".join(parts)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ANN001 - MkDocs hook signature
    if COMMANDS_MARKER in markdown:
        markdown = markdown.replace(COMMANDS_MARKER, command_table())
    if MARKER in markdown:
        markdown = markdown.replace(MARKER, cli_reference())
    return markdown
