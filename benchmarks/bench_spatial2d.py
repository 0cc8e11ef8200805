"""Real pipeline in 2-D: survival per box for both GeoRobusts, random and APGD, from the paper run's store.

The measurement is the paper run's spatial-2d experiment (issue 26: 100 images × 6 boxes × 4 methods, hours on
this CPU), far too long for ``make bench``; its store is committed, packed, in the bundle ``results/paper``. This
section formats what that store holds (:func:`vbl_robust.report.markdown.survival_markdown`: the images every
method completed, and the found / true worst ratios on the image that has the dense landscape grid) and names the
command that produced it and would extend it. Nothing is evaluated here. A run directory ``runs/paper/spatial-2d``
(a run in progress) is read in preference to the bundle.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from vbl_robust.report.markdown import survival_markdown
from vbl_robust.store.core import PACKED, STORE
from vbl_robust.store.pack import restore_store

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT / "results" / "paper" / "spatial-2d"
RUN = ROOT / "runs" / "paper" / "spatial-2d"
COMMAND = "vbl-robust reproduce paper --out runs/paper --resume-from results/paper"


def _section(store_dir: Path, source: str) -> str:
    body = survival_markdown(str(store_dir))
    return body.replace(str(store_dir), source)


def main(quick: bool = False) -> str:
    head = ("## Real pipeline in 2-D: the GeoRobusts, random, APGD (spatial-2d)\n\n"
            "Shipped detector v9 (two-stage, `auto` engine), the paper run's spatial-2d experiment: synthetic "
            "approaches of seed 0, roll × contrast boxes from (±2°, [0.9, 1.1]) to (±30°, [0.4, 2.5]), 200 "
            "evaluations per image and box, early stop at the first breach. Read from its store (the committed "
            f"bundle's `results/paper/spatial-2d/{PACKED}`, or `runs/paper/spatial-2d` while the run goes on); "
            f"produced, and resumed, by `{COMMAND}` (claims and verdicts: `results/paper/claims.md`).\n\n"
            "\"any of them\" is the union of every row's breaches (a lower bound on the true breach count; no "
            "image has a dense 2-D reference besides the first). The landscape grid (61 × 36 points) is coarser "
            "than the roll scale of L (0.1–0.3°), so the searches find values above its maximum (ratios above "
            "1).\n\n")
    if (RUN / STORE).is_file():
        return head + _section(RUN, "runs/paper/spatial-2d")
    if not (BUNDLE / PACKED).is_file():
        return head + "_No committed store: run the command above._\n"
    with tempfile.TemporaryDirectory() as tmp:
        restore_store(BUNDLE / PACKED, Path(tmp))
        return head + _section(Path(tmp), "results/paper/spatial-2d")
