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


#: The floors, lowest first: a module imports only modules of its own floor or of floors below it (``cli`` may
#: import everything). ``search`` sits low: it maximises any batched function over a box and imports nothing of
#: images, detectors or PnP. Top-level helper modules (``atomic``, ``digest``, ``lazy``) are the ground floor. The
#: risk estimators (``risk``) search a box too. A campaign's data (``specs``) and its results store (``store``) sit
#: below the engine that runs it (``campaigns``); what reads a store sits above: ``analysis``, ``report`` (one run),
#: ``paper`` (the paper's claims and bundle).
FLOORS = ("constants", "stats", "space", "atomic", "digest", "lazy", "consent", "search", "risk", "geometry", "data", "scenes",
          "perturb", "pnp", "detect", "pipeline", "sequences", "specs", "store", "campaigns", "analysis", "report",
          "paper", "cli")
#: Arrows up that are still there, each to be removed (issue 46); an arrow up not listed here fails the test, and
#: so does a listed one that is gone (the list shrinks with the code).
KNOWN_UP: set[str] = set()


def _arrows_up(graph: dict[str, set[str]]) -> set[str]:
    rank = {name: i for i, name in enumerate(FLOORS)}

    def floor(module: str) -> int | None:
        parts = module.split(".")
        return rank[parts[1]] if len(parts) > 1 else None

    for module in graph:
        parts = module.split(".")
        assert len(parts) == 1 or parts[1] in rank, f"{module}: on no floor; add it to FLOORS"
    return {f"{m} -> {d}" for m, deps in graph.items() for d in deps
            if floor(m) is not None and floor(d) is not None and floor(d) > floor(m)}


def test_imports_point_down_the_floors():
    assert _arrows_up(_graph()) == KNOWN_UP


def test_the_floor_checker_sees_an_arrow_up():
    assert _arrows_up({"vbl_robust.search.api": {"vbl_robust.pipeline"}, "vbl_robust.pipeline": set()}) == \
        {"vbl_robust.search.api -> vbl_robust.pipeline"}


def test_the_declared_interfaces_are_implemented_where_the_code_relies_on_them():
    """The view samplers a detector reads (Views) and the objectives a campaign searches (SearchObjective)."""
    import numpy as np
    import torch

    from vbl_robust.detect.base import DetectContext, ImageViews, Views
    from vbl_robust.detect.oracle import OracleDetector
    from vbl_robust.pipeline import Objective, SearchObjective
    from vbl_robust.scenes.generate import generate
    from vbl_robust.scenes.sequences import generate_sequences
    from vbl_robust.sequences.objective import SequenceObjective, _StackedViews
    from vbl_robust.space import ParameterBox

    box = ParameterBox({"roll_deg": (-5.0, 5.0)})
    sample = next(iter(generate(1, seed=0, width=96, height=96)))
    objective = Objective(sample, OracleDetector(), box)
    sequence = SequenceObjective(generate_sequences(1, 3, 10.0, seed=0, width=96, height=96)[0], OracleDetector(), box)
    for obj in (objective, sequence):
        assert isinstance(obj, SearchObjective) and obj.device == torch.device("cpu") and obj.image_error == ""
    sampler = objective.context(np.zeros((2, 1))).sampler
    for views in (sampler, ImageViews(torch.zeros(2, 3, 8, 8)), _StackedViews([sampler, sampler])):
        assert isinstance(views, Views)
        assert DetectContext(None, views).device == torch.device("cpu")
