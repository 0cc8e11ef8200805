"""Real pipeline in 2-D: survival per box for both GeoRobusts, random and APGD (issue 17), from a committed run.

The measurement itself is an experiment of hours on this CPU (≈ 5 min per image for four methods on six boxes),
too long for ``make bench``; it is resumable and its store is committed, so this section formats what the store
holds (:func:`vbl_robust.report.markdown.survival_markdown`: the images every method completed, and the found / true worst ratios on the
image that has a dense landscape grid) and names the command that produced it and would extend it. Nothing is
evaluated here.
"""

from __future__ import annotations

from pathlib import Path

from vbl_robust.report.markdown import survival_markdown

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT / "results" / "issue17_spatial2d"
COMMAND = ("mkdir -p runs/issue17_spatial2d && cp results/issue17_spatial2d/results.sqlite runs/issue17_spatial2d/ && "
           "vbl-robust reproduce spatial-2d --images 30 --seed 0 --methods georobust,georobust-a,random,apgd "
           "--out runs/issue17_spatial2d")
#: Runs of the same images added as more rows (bundle, what it is, the command that made it).
OTHERS = (
    ("issue17_spatial2d_av", "georobust-av (georobust-a plus the box's four vertices in its first batch)",
     "vbl-robust reproduce spatial-2d --images 30 --seed 0 --methods georobust-av --no-landscape "
     "--out runs/issue17_spatial2d_av"),
    ("issue17_corners", "the four vertices alone (`grid [counts=[2, 2]]`: a probe, not a search)",
     "vbl-robust reproduce spatial-2d --images 30 --seed 0 --methods grid --method-option 'grid.counts=[2,2]' "
     "--max-evals 4 --no-landscape --out runs/corners"),
)


def main(quick: bool = False) -> str:
    head = ("## Real pipeline in 2-D: the GeoRobusts, random, APGD (spatial-2d)\n\n"
            "Shipped detector (two-stage, `auto` engine), synthetic approaches of `reproduce spatial-2d --seed 0`, "
            "200 evaluations per image and box, early stop at the first breach. Read from the committed store "
            f"`results/issue17_spatial2d/results.sqlite` (`vbl-robust report results/issue17_spatial2d --format md`); "
            f"produced, and resumed or extended, by `{COMMAND}`.\n\n")
    if not (BUNDLE / "results.sqlite").exists():
        return head + "_No committed store: run the command above._\n"
    others = [(ROOT / "results" / name, what, cmd) for name, what, cmd in OTHERS
              if (ROOT / "results" / name / "results.sqlite").exists()]
    if others:
        head += "More rows, from runs of the same images: " + "; ".join(
            f"{what}, `results/{p.name}` (`{cmd}`)" for p, what, cmd in others) + ".\n\n"
    head += ("\"any of them\" is the union of every row's breaches (a lower bound on the true breach count; no "
             "image has a dense 2-D reference besides the first). The landscape grid (61 × 36 points) is coarser than "
             "the roll scale of L (0.1–0.3°), so the searches find values above its maximum (ratios above 1).\n\n")
    body = survival_markdown(str(BUNDLE), tuple(str(p) for p, _, _ in others))
    return head + body.replace(str(BUNDLE), "results/issue17_spatial2d")
