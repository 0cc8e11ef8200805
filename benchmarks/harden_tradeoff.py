"""Issue 29: the trade-off of each hardening try (each round's weights): nominal survival on the validation seeds
paired with v9, against a quick roll screen on the before/after audit's 50 images (seed 0), paired with v9 too.

- nominal: ``benchmarks/detector_protocol.py --split validation --compare v9`` (2040 approaches, exact McNemar).
- screen: ``reproduce spatial-1d --methods georobust-av --max-evals 30 --grid-step 1`` (the roll boxes ±2…±30°, 30
  evaluations per box and a 1° reference grid over ±30°): far fewer evaluations than the full before/after audit
  (``benchmarks/measure_harden.py``), so it finds fewer breaches — a ranking of the tries, not their robustness
  figures. v9 is screened the same way.

The tries: ``vbl-robust harden COMMON <the try's options> --out <its folder>`` (:data:`TRIES`; try1 is the
pre-registered run of ``benchmarks/measure_harden.py``). Outputs in ``results/harden/tradeoff/``
(``TRY_rN_nominal.txt``, ``TRY_rN_validation.json``, ``screen_TRY_rN_compare.md``); a try whose outputs are all there
is skipped, so a new checkout runs only the tries it lacks (training included: harden resumes its rounds, with
``--trust-model``: they are this script's own). Stores stay in ``runs/harden/tradeoff/``. Written then as
``benchmarks/harden_tradeoff.sh`` (git history); the same commands in Python (issue 46). Run it alone on the machine::

    python benchmarks/harden_tradeoff.py             # --dry-run: the commands left to run
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from measure_harden import ROOT, Steps
from vbl_robust.campaigns.harden import Round

SCREEN = ("spatial-1d", "--images", "50", "--methods", "georobust-av", "--max-evals", "30", "--grid-step", "1",
          "--workers", "2", "-q")
COMMON = ("--rounds", "2", "--k", "8", "--epochs", "2", "--n-train", "300", "--n-val", "60")
#: name, training folder, the try's own harden options
TRIES = (
    ("try1", Path("train_runs/harden_roll30"), ("--perturb", "roll_deg=-30,30", "--threads", "1")),
    ("try2", Path("train_runs/harden_roll30_shipped"), ("--perturb", "roll_deg=-30,30", "--data", "shipped",
                                                        "--threads", "2")),
    ("try3", Path("train_runs/harden_roll15_shipped"), ("--perturb", "roll_deg=-15,15", "--data", "shipped",
                                                        "--threads", "2")),
)


def tradeoff(s: Steps, out: Path, res: Path) -> None:
    """Each try of :data:`TRIES` whose outputs are not all in ``res`` (module docstring)."""
    for name, folder, options in TRIES:
        outputs = [res / f for r in (0, 1) for f in (f"{name}_r{r}_validation.json", f"screen_{name}_r{r}_compare.md")]
        if not s.todo(name, *outputs):
            continue
        if s.todo(f"{name}: training", folder / "round01" / Round.RECORD):
            s.vr("harden", *options, *COMMON, "--trust-model", "--out", folder)
        s.vr("reproduce", *SCREEN, "--model", "default", "--out", out / "screen_v9")  # resumes: done once
        for r in (1, 0):
            tag = f"{name}_r{r}"
            w = s.weights(folder, r)
            if s.todo(f"{tag}: nominal protocol", res / f"{tag}_validation.json"):
                s.protocol(w, "validation", res / f"{tag}_validation.json", res / f"{tag}_nominal.txt", tee=False)
            s.vr("reproduce", *SCREEN, "--model", w, "--trust-model", "--detector", "twostage",
                 "--out", out / f"screen_{tag}")
            s.vr("report", out / "screen_v9", "--format", "md", "--compare", out / f"screen_{tag}",
                 out=res / f"screen_{tag}_compare.md", tee=False)
            if not s.dry_run:
                _summary(tag, ROOT / res / f"{tag}_nominal.txt", ROOT / res / f"screen_{tag}_compare.md")


def _summary(tag: str, nominal: Path, screen: Path) -> None:
    """The try's pooled nominal line and its screen at ±2, ±15 and ±30° (all images)."""
    pooled = [line for line in nominal.read_text().splitlines() if line.startswith("| pooled")]
    print(f"{tag}: {pooled[0] if pooled else ''}")
    for line in screen.read_text().splitlines():
        if any(line.startswith(f"| georobust-av | ±{b}° | all ") for b in (2, 15, 30)):
            print(line)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dry-run", action="store_true", help="print the commands left to run, run none")
    ap.add_argument("--out", type=Path, default=Path("runs/harden/tradeoff"), help="the screens' run directories")
    ap.add_argument("--res", type=Path, default=Path("results/harden/tradeoff"), help="the outputs")
    a = ap.parse_args(argv)
    tradeoff(Steps(dry_run=a.dry_run), a.out, a.res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
