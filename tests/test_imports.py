"""The package's import graph: no cycle anywhere, and dependencies that point one way.

Every ``import`` / ``from … import`` inside ``src/vbl_robust`` (at module level and inside functions) is an edge
between modules. A cycle through function-level imports is a cycle too: it only hides the knot.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "vbl_robust"


def _module_name(path: Path) -> str:
    rel = path.relative_to(SRC).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for mod, path in modules.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                # ``from pkg import mod`` depends on the submodule; ``from pkg import name`` on pkg itself
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
            for t in targets:
                if t in modules and t != mod:
                    graph[mod].add(t)
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in state and (c := visit(n)):
                return c
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (c := visit(m)):
            return c
    return None


def test_no_import_cycle():
    assert _cycle(_graph()) is None, " → ".join(_cycle(_graph()))


def test_search_imports_nothing_of_images_detectors_or_pnp():
    g = _graph()
    allowed = {"vbl_robust.space", "vbl_robust.constants"}
    for mod, deps in g.items():
        if mod.startswith("vbl_robust.search"):
            outside = {d for d in deps if not d.startswith("vbl_robust.search")} - allowed
            assert not outside, f"{mod} imports {sorted(outside)}"


def test_perturb_knows_nothing_of_detectors():
    g = _graph()
    for mod, deps in g.items():
        if mod.startswith("vbl_robust.perturb"):
            assert not {d for d in deps if d.startswith(("vbl_robust.detect", "vbl_robust.pipeline"))}, mod


def test_the_checker_sees_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
