"""The documentation: the site builds strictly (mkdocs.yml), the README is a front page, and every command line the
README and the docs show names a real command and real options (checked against the typer app, not by hand).

The build runs in `make test`: a broken link, a missing page, a missing included file or a docstring mkdocstrings
cannot read fails it. A missing tool fails too (never a skip): `pip install -e '.[dev]'` installs it.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest
import typer

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"


def _commands() -> tuple[click.Group, dict[str, click.Command]]:
    from vbl_robust.cli import app

    group = typer.main.get_command(app)
    ctx = click.Context(group, info_name="vbl-robust")
    return group, {name: group.get_command(ctx, name) for name in group.list_commands(ctx)}


def _options(command: click.Command) -> set[str]:
    opts: set[str] = set()
    for param in command.params:
        opts.update(o for o in (*param.opts, *getattr(param, "secondary_opts", ())) if o.startswith("-"))
    return opts | {"-h", "--help"}


@pytest.fixture(scope="module")
def built_site(tmp_path_factory) -> Path:
    assert importlib.util.find_spec("mkdocs") is not None, "mkdocs is not installed: pip install -e '.[dev]'"
    site = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{log[-4000:]}"
    warnings = [line for line in log.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert not warnings, "\n".join(warnings)
    return site


def test_site_builds_strict_with_every_page(built_site: Path) -> None:
    for page in ("index.html", "getting-started.html", "concepts.html", "reference/cli.html", "reference/api.html",
                 "reproduction.html", "benchmarks.html", "model-card.html", "changelog.html", "conventions.html",
                 "security.html", "results/index.html"):
        assert (built_site / page).is_file(), page
    for how_to in ("audit-your-model", "lard-data", "sequences", "zones", "risk", "hardening", "ray", "gpu"):
        assert (built_site / "how-to" / f"{how_to}.html").is_file(), how_to
    # the included files arrive whole: their last generated section is there
    assert "Status of the runs" in (built_site / "reproduction.html").read_text()
    assert "Known limits" in (built_site / "model-card.html").read_text()
    assert (built_site / "assets" / "demo_landscape.png").is_file()


def test_cli_reference_lists_every_command(built_site: Path) -> None:
    html = (built_site / "reference" / "cli.html").read_text()
    _, commands = _commands()
    assert len(commands) >= 10
    for name in commands:
        assert f'id="vbl-robust-{name}"' in html, f"no section for vbl-robust {name}"
        assert f"Usage: vbl-robust {name} [OPTIONS]" in html, name


def _page_text(html: str) -> str:
    """The visible text of a page: tags dropped, entities resolved, whitespace collapsed."""
    import html as html_lib

    return " ".join(html_lib.unescape(re.sub(r"<[^>]+>", " ", html)).split())


def test_cli_reference_is_generated_from_the_command_objects(built_site: Path) -> None:
    """The navigation gives every command's whole summary (never cut by "…"); each command's section has a table
    with a row, and an anchor, for every option — its type and default beside its help."""
    html = (built_site / "reference" / "cli.html").read_text()
    text = _page_text(html)
    group, commands = _commands()
    for name, command in commands.items():
        assert f'href="#vbl-robust-{name}"' in html, name
        summary = " ".join((command.help or "").replace("`", "").split())
        assert summary and summary in text, f"the whole summary of {name} is not on the page"
        section = html.split(f'id="vbl-robust-{name}"', 1)[1].split('<h2 id="vbl-robust-', 1)[0]
        for param in command.params:
            if param.param_type_name != "option" or param.hidden:
                continue
            long = next(o for o in param.opts if o.startswith("--"))
            assert f'id="{name}-{long[2:]}"' in section, f"no row for vbl-robust {name} {long}"
            assert " ".join((param.help or "").split()).replace("`", "")[:40] in _page_text(section), (name, long)
    for param in group.params:
        long = next(o for o in param.opts if o.startswith("--"))
        assert f'id="global-{long[2:]}"' in html, long
    audit = html.split('id="vbl-robust-audit"', 1)[1].split('<h2 id="vbl-robust-', 1)[0]
    assert re.search(r'id="audit-max-evals".*?</td>\s*<td>int 0–\d+</td>\s*<td><span class="cli-default"><code>200</code>',
                     audit, flags=re.S), "the --max-evals row: type and default"
    # pages that link to an option's row link to one that exists (the strict build checks the anchors too)
    for page in DOCS.rglob("*.md"):
        for anchor in re.findall(r"reference/cli\.md#([\w-]+)", page.read_text()):
            assert f'id="{anchor}"' in html, f"{page.relative_to(ROOT)}: #{anchor}"


def test_the_paper_results_page_shows_the_bundle_figures(built_site: Path) -> None:
    """docs/hooks/bundle_figures.py serves results/paper/*/headline.png from where they live; the results page
    shows them and its survival numbers as tables, not slash-separated runs."""
    for figure in (ROOT / "results" / "paper").glob("*/headline.png"):
        assert (built_site / "results" / "paper-figures" / f"{figure.parent.name}.png").is_file(), figure
    page = (DOCS / "results" / "paper.md").read_text()
    assert "paper-figures/spatial-1d.png" in page
    for path in sorted((DOCS / "results").glob("*.md")):
        run = re.search(r"\d[\d.]*(?: ?/ ?\d[\d.]*){2,}", path.read_text())
        assert not run, f"{path.name}: a slash-separated run of numbers, {run.group()!r}: make it a table"


#: The pages a user reads; the project's own history (issues, sessions, commits) belongs in CHANGELOG.md, and the
#: records (REPRODUCTION.md, BENCHMARKS.md, the model card) may name the commits their numbers were measured at.
USER_PAGES = ("index.md", "getting-started.md", "concepts.md", "conventions.md", "security.md", "how-to/*.md",
              "reference/*.md", "results/*.md")


def test_user_pages_carry_no_project_history() -> None:
    history = re.compile(r"\b(?:issues?|sessions?) \d+|`[0-9a-f]{7,40}`|\bthis project.s sessions\b",
                         flags=re.I)
    for pattern in USER_PAGES:
        for page in sorted(DOCS.glob(pattern)):
            found = history.search(page.read_text())
            assert not found, f"{page.relative_to(ROOT)}: {found.group()!r} is project history (CHANGELOG.md)"


def test_api_reference_is_generated_from_docstrings(built_site: Path) -> None:
    html = (built_site / "reference" / "api.html").read_text()
    for name in ("ParameterBox", "Objective", "maximize", "run_campaign", "clopper_pearson"):
        assert name in html, name
    assert "::: vbl_robust" not in html  # every directive rendered


def test_readme_is_a_front_page() -> None:
    text = README.read_text()
    lines = text.splitlines()
    assert len(lines) <= 150, f"README has {len(lines)} lines (at most 150)"
    first_block = text.split("```", 2)[1]
    assert re.search(r"^make demo\b", first_block, re.M) and re.search(r"^make test\b", first_block, re.M)
    assert text.index("make demo") < text.index("## "), "README must start with make demo / make test"
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text) + re.findall(r'<img src="([^"]+)"', text)
    assert "docs/assets/demo_landscape.png" in links, "the README shows the demo's figure"
    for target in links:
        if "://" in target:
            continue
        assert (ROOT / target).exists(), f"README links to {target}, which is not there"
    assert "REPRODUCTION.md" in text and "docs/" in text


def _shown_commands(text: str) -> list[str]:
    """Every `vbl-robust …` command line of a Markdown text: code blocks (continuation lines joined) and inline
    code spans."""
    found: list[str] = []
    for block in re.findall(r"```(?:bash|sh|console)?\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #", 1)[0].strip()
            if line.startswith("vbl-robust "):
                found.append(line)
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    found += [span for span in re.findall(r"`([^`\n]+)`", prose) if span.startswith("vbl-robust ")]
    return found


def _markdown_files() -> list[Path]:
    return [README, ROOT / "CHANGELOG.md", *sorted(DOCS.rglob("*.md"))]


def test_shown_commands_name_real_options() -> None:
    group, commands = _commands()
    global_opts = _options(group)
    problems: list[str] = []
    checked = 0
    for path in _markdown_files():
        for line in _shown_commands(path.read_text()):
            words = [w for w in line.split()[1:] if w not in global_opts]
            name = words[0] if words else ""
            if name in ("COMMAND", "…", "..."):  # a placeholder, not a command
                continue
            if name not in commands:
                problems.append(f"{path.relative_to(ROOT)}: unknown command in `{line}`")
                continue
            valid = _options(commands[name])
            for opt in re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", " ".join(words[1:])):
                if opt not in valid:
                    problems.append(f"{path.relative_to(ROOT)}: `vbl-robust {name}` has no option {opt} (`{line}`)")
            checked += 1
    assert checked >= 40, f"only {checked} command lines found"
    assert not problems, "\n".join(problems)


def test_shown_make_targets_exist() -> None:
    targets = set(re.findall(r"^([a-z][\w-]*):", (ROOT / "Makefile").read_text(), flags=re.M))
    for path in _markdown_files():
        text = path.read_text()
        code = re.findall(r"```.*?```", text, flags=re.S) + re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
        for target in re.findall(r"(?:^|\s|&&\s*)make ([a-z][\w-]*)", "\n".join(code), flags=re.M):
            assert target in targets, f"{path.relative_to(ROOT)}: `make {target}` is no Makefile target"


#: A command on the committed paper bundle, as the docs print it in inline code: `vbl-robust report|zones
#: results/paper/EXPERIMENT …`.
BUNDLE_COMMAND = re.compile(r"`(vbl-robust (?:report|zones) results/paper/[^`]+)`")


def _bundle_commands() -> list[str]:
    found = set()
    for page in [README, ROOT / "REPRODUCTION.md", *DOCS.rglob("*.md")]:
        found.update(BUNDLE_COMMAND.findall(page.read_text()))
    return sorted(found)


def test_the_docs_name_commands_on_the_committed_bundle() -> None:
    """Guard for the test below: the docs do print such commands (and none on a run directory a fresh clone lacks)."""
    assert len(_bundle_commands()) >= 3
    for page in DOCS.rglob("*.md"):
        assert not re.search(r"`vbl-robust (?:report|zones) runs/paper/", page.read_text()), page


@pytest.mark.slow
@pytest.mark.parametrize("line", _bundle_commands())
def test_every_command_the_docs_print_on_the_bundle_runs(line: str, full: bool) -> None:
    """Each `vbl-robust report|zones results/paper/…` line of the docs runs on the committed bundle — its packed
    store read through a temporary copy — and exits 0 (nothing in the bundle is unmeasured), writing nothing into
    the bundle. Without --full, the smallest stores only."""
    import shlex

    from typer.testing import CliRunner

    from vbl_robust.cli import app

    args = shlex.split(line)[1:]
    store = ROOT / args[1] / "results.sqlite.xz"
    assert store.is_file(), store
    if not full and store.stat().st_size > 4_000_000:
        pytest.skip(f"{args[1]}: a {store.stat().st_size / 1e6:.1f} MB packed store runs under --full")
    before = {p: p.stat().st_mtime_ns for p in (ROOT / args[1]).rglob("*")}
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output[-2000:]
    assert result.stdout.strip()
    assert {p: p.stat().st_mtime_ns for p in (ROOT / args[1]).rglob("*")} == before
