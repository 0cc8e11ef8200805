"""The options several commands take, declared once: a command writes ``seed: int = o.SEED`` after
``from . import options as o``."""

from __future__ import annotations

import typer

from ..constants import MAX_IMAGE_SIDE, MAX_SEED

QUIET = typer.Option(False, "--quiet", "-q", help="No progress bar or tables (also accepted before the command: "
                     "vbl-robust -q COMMAND).")
VERBOSE = typer.Option(False, "--verbose", "-v", help="Log progress details (INFO) (also accepted before the "
                       "command: vbl-robust -v COMMAND).")
SEED = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Seed of the image choice and of the searches.")
LARD = typer.Option(None, "--lard", help="LARD V2 dataset directory (CSV + runway DB JSON) instead of generated "
                    "synthetic approaches.")
WIDTH = typer.Option(1024, "--width", min=16, max=MAX_IMAGE_SIDE, help=f"Synthetic image width (px, at most "
                     f"{MAX_IMAGE_SIDE}).")
HEIGHT = typer.Option(1024, "--height", min=16, max=MAX_IMAGE_SIDE, help=f"Synthetic image height (px, at most "
                      f"{MAX_IMAGE_SIDE}).")
MODEL = typer.Option(None, "--model", help="Detector: a YOLO-pose .pt or .onnx file, 'default' for the shipped "
                     "model, or 'hardened' for the shipped model hardened by vbl-robust harden once installed "
                     "(default: the shipped model once it is validated, else the oracle).")
TRUST_MODEL = typer.Option(False, "--trust-model", help="Allow loading a .pt pickle from outside the package.")
DESIGN = typer.Option("auto", "--detector", help="Detector design: auto (the shipped model's own; a user's model as "
                      "one pass), single (one pass: the paper's pipeline) or twostage.")
ENGINE = typer.Option("auto", "--engine", help="Inference engine of the black-box path: auto (ONNX Runtime when "
                      "installed), torch, onnxruntime or openvino — always fp32; the outputs stay within 1e-3 px of "
                      "torch's, APGD stays on torch.")
DEVICE = typer.Option("cpu", "--device", help="Where the pipeline runs: cpu (default), cuda, cuda:N, or auto (CUDA "
                      "when available). On a GPU the perturbation, views, detector and differentiable PnP run there; "
                      "--engine auto then means torch.")
ORACLE = typer.Option(False, "--oracle", help="Use the oracle detector (exact projected corners).")
ORACLE_NOISE = typer.Option(0.0, "--oracle-noise", min=0.0, help="Oracle: fixed per-image corner noise (px).")
METHOD_OPTION = typer.Option(None, "--method-option", help="A search method's option, METHOD.OPTION=VALUE "
                             "(repeatable; VALUE read as YAML: 9, 0.5, true, [3, 5]), e.g. georobust-a.min_ratio=9 or "
                             "georobust.alpha=3; recorded in the store and the job keys.")
EXECUTOR = typer.Option("local", "--executor", help="local or ray.")
ADDRESS = typer.Option(None, "--address", help="Ray cluster address (default: start a local Ray); checked before "
                       "the run (10 s).")
WORKERS = typer.Option(0, "--workers", help="Worker processes of a local run, one torch thread each (default 0: one "
                       "per core, or $VBL_ROBUST_WORKERS); 1 runs in this process.")
CLOCK = typer.Option("auto", "--clock", help="Clock of time budgets: process (CPU seconds of the evaluating process, "
                     "which other work on the machine does not move), wall, or auto (process on a CPU, wall on a "
                     "GPU). Recorded with the results.")
WAIT = typer.Option(False, "--wait", help="When another run is writing the same --out, wait for it to end instead of "
                    "refusing.")
RETRY_FAILED = typer.Option(False, "--retry-failed", help="Run the jobs stored as failed again (e.g. after a missing "
                            "image was restored); a plain rerun skips them.")
CSV = typer.Option(None, "--csv", help="Also export the job rows to this CSV file.")
PARQUET = typer.Option(None, "--parquet", help="Also export the job rows to this Parquet file.")
REPORT = typer.Option(True, "--report/--no-report", help="Write report.html into --out.")
from .config import CONFIG  # noqa: E402  (declared beside what it reads; listed here with the other shared options)
