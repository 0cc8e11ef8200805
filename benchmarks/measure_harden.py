"""Issue 29: harden the shipped detector (v9) against camera roll, then measure it before / after, paired per image.

Fixed before any hardening run (2026-12-03, session 32), so that no choice is made on the figures it produces:

- training: roll ±30° (the largest 1-D box the audit reads), worst of k = 8 per image (plus the image's previous
  worst), 2 rounds × 2 epochs, 300 approaches of ``detect.protocol.HARDEN_SEED`` (their own airports) with their
  clean views, 60 clean validation approaches, v9's own recipe (``detect.train.FINE_TUNE``); the weights of the last
  round.
- nominal: ``benchmarks/detector_protocol.py`` on every seed (the model card's figures need the test seeds); the four
  validation seeds (2040 approaches) paired with v9's committed results (exact McNemar): the goal is p >= 0.05 and no
  worse than -1 point. Then shipped beside v9 (``ship --as hardened``; it replaces nothing) and audited as
  ``--model hardened``.
- spatial-1d: the paper's experiment (roll ±2…±30°, georobust / georobust-av / random / apgd, dense-grid truth) on the
  first 50 images of seed 0 with the hardened model; "before" is the paper run's v9 store on the same images
  (``runs/paper/spatial-1d``, unpacked from its committed bundle ``results/paper`` on a new checkout).
- 2-D box: roll ±15° × contrast [0.7, 1.4], the four methods, 200 evaluations with early stop, 50 images of seed 0,
  both models.
- transfer: brightness [-0.2, 0.2] (never trained on), the same way, both models.

Written then as ``benchmarks/measure_harden.sh`` (git history); this is the same sequence of commands in Python
(issue 46). Every step is skipped when its outputs are there, and the stores and the harden rounds resume (the
training passes ``--trust-model``: the rounds it resumes are its own), so running it again goes on where it stopped:
each audit's store is packed into ``results/harden/audits/<run>/`` (``vbl-robust bundle --stores``, after each step,
and by hand before a session stops: the KEEP line below) and a run directory without its store restores it from
there (``vbl-robust merge``). The measurement is complete: git keeps its tables, job tables and ``compare.html``, not
the packed stores or reports (docs/conventions.md; git ignores the stores packed there, ``results/README.md`` says
how to restore them as measured), so a clean clone finds every step done; removing a step's outputs (its
``*_compare.md`` and ``compare.html``) measures it again (steps 3–5: about 4.4 h with two workers). One thread per
process; run it alone on the machine (it is CPU-bound for hours)::

    python benchmarks/measure_harden.py             # all of it; --dry-run: the commands left to run
    .venv/bin/vbl-robust bundle runs/harden/audits --out results/harden/audits --stores   # KEEP: pack what is done

The helpers (:class:`Steps`) also run ``benchmarks/harden_tradeoff.py``.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from vbl_robust.atomic import atomic_write
from vbl_robust.campaigns.harden import Round

ROOT = Path(__file__).resolve().parents[1]
#: The environment of every command (one thread per process, offline, no windows).
ENV = {"OMP_NUM_THREADS": "1", "YOLO_OFFLINE": "1", "YOLO_VERBOSE": "False", "MPLBACKEND": "Agg"}
#: v9's committed validation protocol, the pairing of every nominal comparison.
V9_PROTOCOL = Path("results/detector_candidates/protocol_v9_validation.json")
#: The pre-registered training (the folder is --harden-dir).
TRAINING = ("--perturb", "roll_deg=-30,30", "--rounds", "2", "--k", "8", "--epochs", "2", "--n-train", "300",
            "--n-val", "60", "--threads", "1")
SHIPPED = Path("src/vbl_robust/models/hardened/runway_yolov8n_pose.pt")
RES = Path("results/harden")
N = "50"
METHODS = "georobust,georobust-av,random,apgd"
#: The two audits of both models: name, their box options.
CASES = (("box2d", ("--roll", "15", "--contrast", "0.7,1.4")),
         ("transfer", ("--roll", "none", "--perturb", "brightness=-0.2,0.2")))


class Steps:
    """Runs a workflow's commands from the repository root, each step only when some of its outputs are missing
    (a rerun goes on where the last one stopped); ``dry_run`` prints the commands instead of running them.
    ``vr`` and ``py``: the ``vbl-robust`` and ``python`` to run (default: this interpreter's; ``$VR``, ``$PY``)."""

    def __init__(self, *, dry_run: bool = False, vr: str | None = None, py: str | None = None):
        self.dry_run = dry_run
        self.vr_bin = vr or os.environ.get("VR") or str(Path(sys.executable).with_name("vbl-robust"))
        self.py = py or os.environ.get("PY") or sys.executable
        self.commands: list[list[str]] = []  # every command run (or printed), in order

    def todo(self, name: str, *outputs: Path) -> bool:
        """Whether step ``name`` has work left: some of ``outputs`` missing (none given: always)."""
        if outputs and all((ROOT / p).exists() for p in outputs):
            print(f"{name}: done ({', '.join(map(str, outputs))})", flush=True)
            return False
        print(f"{name}: to do", flush=True)
        return True

    def run(self, cmd: Sequence[object], *, cwd: Path = ROOT, out: Path | None = None, tee: bool = True) -> None:
        """Run ``cmd`` (stops the workflow when it fails); ``out``: its standard output is written there once it
        succeeded (and echoed with ``tee``)."""
        args = [str(a) for a in cmd]
        print("+", shlex.join(args), *([">", str(out)] if out is not None else []), flush=True)
        self.commands.append(args)
        if self.dry_run:
            return
        env = {**os.environ, **ENV}
        if out is None:
            subprocess.run(args, cwd=cwd, env=env, check=True)
            return
        lines: list[str] = []
        with subprocess.Popen(args, cwd=cwd, env=env, stdout=subprocess.PIPE, text=True) as proc:
            for line in proc.stdout:
                lines.append(line)
                if tee:
                    sys.stdout.write(line)
        if proc.returncode:
            raise subprocess.CalledProcessError(proc.returncode, args)
        (ROOT / out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write(ROOT / out, "".join(lines))

    def vr(self, *args: object, out: Path | None = None, tee: bool = True) -> None:
        self.run([self.vr_bin, *args], out=out, tee=tee)

    def protocol(self, weights: str, split: str, json_out: Path, nominal: Path, *, tee: bool = True) -> None:
        """``benchmarks/detector_protocol.py`` on ``weights`` (run from ``benchmarks/``), paired with v9's validation
        results; its table into ``nominal``."""
        here = ROOT / "benchmarks"
        self.run([self.py, "detector_protocol.py", "--model", weights, "--split", split, "--json",
                  os.path.relpath(ROOT / json_out, here), "--compare", os.path.relpath(ROOT / V9_PROTOCOL, here)],
                 cwd=here, out=nominal, tee=tee)

    def weights(self, harden_dir: Path, index: int) -> str:
        """The absolute path of round ``index``'s weights (a placeholder in a dry run before the round exists)."""
        rdir = ROOT / harden_dir / f"round{index:02d}"
        if self.dry_run and not (rdir / Round.RECORD).exists():
            return f"<weights of {harden_dir}/round{index:02d}>"
        return str((ROOT / Round.read(rdir).weights).resolve())

    def restore(self, packed: Path, run_dir: Path) -> None:
        """Seed a run directory of this checkout from its packed store when it has none."""
        if (ROOT / packed).is_file() and self.todo(f"restore {run_dir}", run_dir / "results.sqlite"):
            self.vr("merge", packed, "--into", run_dir)


def measure(s: Steps, harden_dir: Path, out: Path, keep: Path) -> None:
    """The whole pre-registered measurement (module docstring)."""
    # 1.-2. training, nominal accuracy on every protocol seed (the validation seeds paired with v9), shipped beside v9
    # as `hardened` version 1; skipped where the model is shipped and measured
    if s.todo("1.-2. training, nominal protocol, ship --as hardened", SHIPPED, RES / "protocol_all.json"):
        if s.todo("training", harden_dir / "round01" / Round.RECORD):
            s.vr("harden", *TRAINING, "--trust-model", "--out", harden_dir)
        w = s.weights(harden_dir, 1)
        if s.todo("nominal protocol", RES / "protocol_all.json", RES / "nominal.txt"):
            s.protocol(w, "all", RES / "protocol_all.json", RES / "nominal.txt")
        s.vr("ship", w, "--as", "hardened", "--version", "1", "--epochs", "52", "--protocol",
             RES / "protocol_all.json", "--trust-model")
    hardened = ("--model", "hardened")
    # 3. spatial-1d, hardened, on the paper run's first 50 images; compared with the paper run's v9 rows ("before":
    # the paper run's store, unpacked from its committed bundle on a checkout without it)
    if s.todo("3. spatial-1d", RES / "spatial1d_compare.md", keep / "spatial-1d" / "compare.html"):
        s.restore(Path("results/paper/spatial-1d/results.sqlite.xz"), Path("runs/paper/spatial-1d"))
        s.restore(keep / "spatial-1d" / "results.sqlite.xz", out / "spatial-1d")
        s.vr("reproduce", "spatial-1d", "--images", N, *hardened, "--out", out / "spatial-1d", "-q")
        s.vr("bundle", out, "--out", keep, "--stores")
        s.vr("report", "runs/paper/spatial-1d", "--compare", out / "spatial-1d", "--out", keep / "spatial-1d")
        s.vr("report", "runs/paper/spatial-1d", "--format", "md", "--compare", out / "spatial-1d",
             out=RES / "spatial1d_compare.md")
    # 4. one 2-D box and 5. the transfer family: both models, the same images and seeds
    for name, box in CASES:
        v9, after = out / f"{name}_v9", out / f"{name}_hardened"
        if not s.todo(f"{name}: v9 against hardened", RES / f"{name}_compare.md", keep / after.name / "compare.html"):
            continue
        for run in (v9, after):
            s.restore(keep / run.name / "results.sqlite.xz", run)
        audit = ("audit", "--images", N, *box, "--methods", METHODS, "--no-landscape")
        s.vr(*audit, "--model", "default", "--out", v9, "-q")
        s.vr(*audit, *hardened, "--out", after, "-q")
        s.vr("bundle", out, "--out", keep, "--stores")
        s.vr("report", v9, "--compare", after, "--out", keep / after.name)
        s.vr("report", v9, "--format", "md", "--compare", after, out=RES / f"{name}_compare.md")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dry-run", action="store_true", help="print the commands left to run, run none")
    ap.add_argument("--harden-dir", type=Path, default=Path("train_runs/harden_roll30"), help="the training's folder")
    ap.add_argument("--out", type=Path, default=Path("runs/harden/audits"), help="the audits' run directories")
    ap.add_argument("--keep", type=Path, default=Path("results/harden/audits"), help="their packed bundle")
    a = ap.parse_args(argv)
    measure(Steps(dry_run=a.dry_run), a.harden_dir, a.out, a.keep)
    return 0


if __name__ == "__main__":
    sys.exit(main())
