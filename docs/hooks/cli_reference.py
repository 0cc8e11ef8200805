"""MkDocs hook: the CLI reference page, generated from the typer app at build time.

``docs/reference/cli.md`` holds the marker ``<!-- cli-reference -->``; this hook replaces it with one section per
command of ``vbl_robust.cli.app``: its one-line summary and its ``--help`` text, exactly as the terminal prints
it (click's own formatter, 88 columns). A command added to the CLI appears here without editing the page.
"""

from __future__ import annotations

import click
import typer

MARKER = "<!-- cli-reference -->"
WIDTH = 88


def _help(command: click.Command, name: str, parent: click.Context | None) -> str:
    ctx = click.Context(command, info_name=name, parent=parent, terminal_width=WIDTH, max_content_width=WIDTH,
                        **command.context_settings)
    return command.get_help(ctx)


def cli_reference() -> str:
    """Markdown for every command of the ``vbl-robust`` app (main help first, then the commands in order)."""
    from vbl_robust.cli import app

    group = typer.main.get_command(app)
    root = click.Context(group, info_name="vbl-robust", terminal_width=WIDTH, max_content_width=WIDTH,
                         **group.context_settings)
    names = list(group.list_commands(root))
    parts = ["| command | what it does |", "|---|---|"]
    for name in names:
        summary = group.get_command(root, name).get_short_help_str(limit=200)
        parts.append(f"| [`{name}`](#vbl-robust-{name}) | {summary} |")
    parts += ["", "## vbl-robust", "", "```text", _help(group, "vbl-robust", None), "```", ""]
    for name in names:
        parts += [f"## vbl-robust {name}", "", "```text", _help(group.get_command(root, name), name, root), "```", ""]
    return "\n".join(parts)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ANN001 - MkDocs hook signature
    if MARKER in markdown:
        return markdown.replace(MARKER, cli_reference())
    return markdown
