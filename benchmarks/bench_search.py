"""Search benchmark: DIRECT family vs scipy/NLopt on the classic functions; every method on cheap landscapes.

Run: ``.venv/bin/python benchmarks/bench_search.py [--quick]``.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from vbl_robust.search import METHODS, maximize
from vbl_robust.search.classic import CLASSIC, Count, count_nlopt, count_ours, count_scipy
from vbl_robust.space import ParameterBox

OURS = [("direct", {}), ("direct-l", {}), ("georobust α=1", {"alpha": 1}), ("georobust α=2", {"alpha": 2}),
        ("georobust α=3", {"alpha": 3})]
NLOPT = ["GN_DIRECT", "GN_DIRECT_L", "GN_ORIG_DIRECT", "GN_ORIG_DIRECT_L"]


def _cell(c: Count, with_nit: bool = True) -> str:
    if c.nfev is None:
        return "—"
    return f"{c.nfev} ({c.nit})" if with_nit and c.nit is not None else str(c.nfev)


def classic_table(max_evals: int) -> str:
    head = [name for name, _ in OURS] + ["scipy DIRECT", "scipy DIRECT-L"] + [f"NLopt {a}" for a in NLOPT]
    rows, firsts = [], []
    for fname, t in CLASSIC.items():
        ours = [count_ours(t, m.split(" ")[0], max_evals=max_evals, **kw) for m, kw in OURS]
        sp = [count_scipy(t, locally_biased=lb, max_evals=max_evals) for lb in (False, True)]
        nl = [count_nlopt(t, a, max_evals=max_evals) for a in NLOPT]
        rows.append(f"| {fname} | " + " | ".join([_cell(c) for c in ours + sp] + [_cell(c, False) for c in nl]) + " |")
        firsts.append(f"| {fname} | " + " | ".join("—" if c.first is None else str(c.first) for c in ours) + " |")
    out = [
        "Evaluations until the best value is within 0.01 % of f* (iterations = batches in parentheses; "
        f"ours are checked after whole iterations; scipy stops by `f_min_rtol`, NLopt by `stopval`; "
        f"— = not reached in {max_evals} evaluations).",
        "",
        "| function | " + " | ".join(head) + " |",
        "|---" * (len(head) + 1) + "|",
        *rows,
        "",
        "Index of the first evaluation that reached the target (ours):",
        "",
        "| function | " + " | ".join(name for name, _ in OURS) + " |",
        "|---" * (len(OURS) + 1) + "|",
        *firsts,
    ]
    return "\n".join(out)


def _xp(x):
    return torch if isinstance(x, torch.Tensor) else np


def landscape_1d(x):
    """Positive, multimodal, with a narrow peak near a = 2.1 (a stand-in for a failure zone)."""
    xp, a = _xp(x), x[:, 0]
    return 2 + xp.sin(3 * a) + 0.6 * xp.sin(7.3 * a + 1) + 1.5 * xp.exp(-((a - 2.1) ** 2) / 0.02)


def landscape_2d(x):
    xp, a, b = _xp(x), x[:, 0], x[:, 1]
    return (3 + xp.sin(3 * a) * xp.cos(2 * b) + 0.5 * xp.sin(5.1 * a + 2 * b)
            + 2 * xp.exp(-((a - 1.3) ** 2 + (b + 0.7) ** 2) / 0.05))


LANDSCAPES = [
    ("1-D", landscape_1d, ParameterBox({"a": (-5.0, 5.0)}), 200_001),
    ("2-D", landscape_2d, ParameterBox({"a": (-3.0, 3.0), "b": (-2.0, 2.0)}), 1501),
]


def landscape_table(budgets: list[int], seeds: int) -> str:
    out = []
    for label, f, box, per_dim in LANDSCAPES:
        dense = maximize(f, box, "grid", counts=per_dim, batch_size=1 << 18, max_evals=per_dim**box.dim)
        out += [
            f"**{label}** `{f.__name__}` on {box!r}: dense grid maximum {dense.fun:.6f} ({dense.nfev} points). "
            f"Best value found / that maximum, mean over {seeds} seeds (seed-free methods: one run); "
            "iterations (batches) at the largest budget in the last column.",
            "",
            "| method | " + " | ".join(f"{b} evals" for b in budgets) + " | batches |",
            "|---" * (len(budgets) + 2) + "|",
        ]
        for method in METHODS:
            n_seeds = seeds if method in ("random", "sobol", "apgd") else 1
            ratios, nit = [], 0
            for b in budgets:
                runs = [maximize(f, box, method, max_evals=b, seed=s) for s in range(n_seeds)]
                ratios.append(np.mean([r.fun for r in runs]) / dense.fun)
                nit = runs[0].nit
            out.append(f"| {method} | " + " | ".join(f"{v:.4f}" for v in ratios) + f" | {nit} |")
        out.append("")
    return "\n".join(out)


def main(quick: bool = False) -> str:
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    max_evals = 6000 if quick else 20000
    budgets = [25, 50, 100, 200] if quick else [25, 50, 100, 200, 400, 800]
    seeds = 2 if quick else 5
    body = [
        "## Search: DIRECT family vs scipy / NLopt, and every method on cheap landscapes",
        "",
        f"Command: `.venv/bin/python benchmarks/bench_search.py{' --quick' if quick else ''}`",
        "",
        "### Classic functions (minimised; ours maximise −f)",
        "",
        classic_table(max_evals),
        "",
        "### Best value vs evaluations, as a ratio to the dense-grid maximum",
        "",
        landscape_table(budgets, seeds),
        f"_Measured in {time.perf_counter() - t0:.1f} s._",
    ]
    return "\n".join(body)


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
