"""Real pipeline in 2-D: survival per box for both GeoRobusts, random and APGD (issue 17), from a committed run.

The measurement itself is an experiment of hours on this CPU (≈ 5 min per image for four methods on six boxes),
too long for ``make bench``; it is resumable and its store is committed, so this section formats what the store
holds (:mod:`tools.survival_table`: the images every method completed, and the found / true worst ratios on the
image that has a dense landscape grid) and names the command that produced it and would extend it. Nothing is
evaluated here.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT / "results" / "issue17_spatial2d"
COMMAND = ("mkdir -p runs/issue17_spatial2d && cp results/issue17_spatial2d/results.sqlite runs/issue17_spatial2d/ && "
           "vbl-robust reproduce spatial-2d --images 30 --seed 0 --methods georobust,georobust-a,random,apgd "
           "--out runs/issue17_spatial2d")


def _tool():
    spec = importlib.util.spec_from_file_location("survival_table", ROOT / "tools" / "survival_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main(quick: bool = False) -> str:
    head = ("## Real pipeline in 2-D: GeoRobust, georobust-a, random, APGD (spatial-2d)\n\n"
            "Shipped detector (two-stage, `auto` engine), synthetic approaches of `reproduce spatial-2d --seed 0`, "
            "200 evaluations per image and box, early stop at the first breach. Read from the committed store "
            f"`results/issue17_spatial2d/results.sqlite` (`python tools/survival_table.py results/issue17_spatial2d`); "
            f"produced, and resumed or extended, by `{COMMAND}`.\n\n")
    if not (BUNDLE / "results.sqlite").exists():
        return head + "_No committed store: run the command above._\n"
    return head + _tool().survival_markdown(str(BUNDLE)).replace(str(BUNDLE), "results/issue17_spatial2d")
