"""The counts issue 58 (the typed layer one floor higher) sets goals on, measured on the working tree.

``python benchmarks/house_counts.py [--json]`` prints, for ``src/vbl_robust``:

- ``lines`` / ``campaigns_lines``: lines of Python in the package and in ``campaigns/``;
- ``campaign_dict_sites``: calls of ``.campaign()`` outside the store package plus subscripts ``[...]["spec"]`` /
  ``camp["spec"]`` (a stored campaign decoded by hand);
- ``kind_literal_comparisons``: ``==`` / ``!=`` / ``in`` / ``not in`` comparisons whose left side is a name or
  attribute called ``kind``, ``role``, ``status``, ``reason``, ``verdict`` or ``failure`` (or ending in ``_kind`` …)
  and whose right side is a string literal or a tuple/set/list of them — a vocabulary compared as text instead of
  through its enum;
- ``settings_declarations``: classes that declare the pipeline settings as fields of their own (ε_safe, the
  penalty, τ_conf and the PnP solver: ``eps_safe_m``, ``penalty_m``, ``conf_threshold``, ``pnp``) — "settings
  declared once" is 1;
- ``all_entries``: names listed in every ``__all__``;
- ``cli_function_imports``: ``import`` statements inside functions under ``cli/``;
- ``audit_parameters`` / ``audit_own_parameters``: parameters of the ``audit`` command function, and those of them
  whose option is declared in ``cli/audit.py`` itself (not a shared declaration of ``cli/options.py``);
- ``results_mb_besides_paper_stores``: tracked bytes under ``results/`` less ``results/paper/*/results.sqlite.xz``;
- ``report_html_over_1mb``: tracked ``*.html`` files over 1 MB.

The numbers are counts of the code, not judgements; the note of issue 58 quotes them before and after.
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "src" / "vbl_robust"
VOCAB = ("kind", "role", "status", "reason", "verdict", "failure")
#: The fields that make a class a declaration of the pipeline settings (``settings_declarations``).
SETTINGS = {"eps_safe_m", "penalty_m", "conf_threshold", "pnp"}


def _named(node: ast.AST) -> bool:
    name = node.attr if isinstance(node, ast.Attribute) else node.id if isinstance(node, ast.Name) else ""
    return any(name == v or name.endswith(f"_{v}") for v in VOCAB)


def _literal(node: ast.AST) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    if isinstance(node, ast.Tuple | ast.Set | ast.List):
        return bool(node.elts) and all(isinstance(e, ast.Constant) and isinstance(e.value, str) for e in node.elts)
    return False


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"))


def _is_store(path: Path) -> bool:
    return "store" in path.relative_to(PKG).parts[:-1]


def counts() -> dict[str, float | int]:
    files = sorted(PKG.rglob("*.py"))
    out: dict[str, float | int] = {
        "lines": 0, "campaigns_lines": 0, "campaign_dict_sites": 0, "kind_literal_comparisons": 0,
        "settings_declarations": 0, "all_entries": 0, "cli_function_imports": 0, "audit_parameters": 0, "audit_own_parameters": 0,
    }
    for path in files:
        text = path.read_text(encoding="utf-8")
        n = text.count("\n")
        out["lines"] += n
        rel = path.relative_to(PKG)
        if rel.parts[0] == "campaigns":
            out["campaigns_lines"] += n
        tree = _tree(path)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "campaign"
                    and not node.args and not _is_store(path)):
                out["campaign_dict_sites"] += 1
            if (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant)
                    and node.slice.value == "spec"):
                out["campaign_dict_sites"] += 1
            if isinstance(node, ast.Compare) and _named(node.left):
                out["kind_literal_comparisons"] += sum(
                    1 for op, right in zip(node.ops, node.comparators, strict=True)
                    if isinstance(op, ast.Eq | ast.NotEq | ast.In | ast.NotIn) and _literal(right))
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__"
                                                    for t in node.targets):
                value = node.value
                if isinstance(value, ast.List | ast.Tuple):
                    out["all_entries"] += len(value.elts)
                elif (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "sorted"
                      and value.args and isinstance(value.args[0], ast.Name)):
                    lazy = _lazy_size(tree, value.args[0].id)
                    out["all_entries"] += lazy
            if isinstance(node, ast.ClassDef) and SETTINGS <= {
                    f.target.id for f in node.body if isinstance(f, ast.AnnAssign) and isinstance(f.target, ast.Name)}:
                out["settings_declarations"] += 1
            if rel.parts[0] == "cli" and isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                out["cli_function_imports"] += sum(1 for sub in ast.walk(node)
                                                   if isinstance(sub, ast.Import | ast.ImportFrom))
            if (rel == Path("cli/audit.py") and isinstance(node, ast.FunctionDef) and node.name == "audit"):
                params = node.args.args + node.args.kwonlyargs
                out["audit_parameters"] = len(params)
                # its own: declared in audit.py (a bare name), not a shared declaration of cli/options.py (o.NAME)
                out["audit_own_parameters"] = sum(1 for a in params if isinstance(a.annotation, ast.Name))
    out.update(_repository())
    return out


def _lazy_size(tree: ast.Module, name: str) -> int:
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, ast.AnnAssign) else []
        if any(isinstance(t, ast.Name) and t.id == name for t in targets) and isinstance(node.value, ast.Dict):
            return len(node.value.keys)
    return 0


def _repository() -> dict[str, float | int]:
    listed = subprocess.run(["git", "ls-files", "-z", "-s", "--", "results", "*.html"], cwd=ROOT, check=True,
                            capture_output=True).stdout.split(b"\0")
    results = 0
    big_html = 0
    for entry in filter(None, listed):
        path = entry.split(b"\t", 1)[1].decode()
        file = ROOT / path
        if not file.is_file():
            continue
        size = file.stat().st_size
        if path.startswith("results/") and not (path.startswith("results/paper/")
                                                 and path.endswith("results.sqlite.xz")):
            results += size
        if path.endswith(".html") and size > 1_000_000:
            big_html += 1
    return {"results_mb_besides_paper_stores": round(results / 1e6, 1), "report_html_over_1mb": big_html}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    values = counts()
    if args.json:
        print(json.dumps(values, sort_keys=True))
    else:
        for key, value in values.items():
            print(f"{key:34s} {value}")


if __name__ == "__main__":
    main()
