"""The options several commands take, declared once as typer ``Annotated`` types: a command writes
``seed: o.Seed = 0`` after ``from . import options as o`` (the default stays at the parameter, as typer wants it).
Where a command words or bounds a shared option its own way (``risk --max-evals`` counts estimator evaluations, up
to 1,000,000), it takes a :func:`variant` of the declaration here: the option's name and kind stay declared once.
A command's own options are declared beside it, in its module; the families of options that several campaigns read
together (images, detector, box, how a run runs, what it writes) become one request object each
(:mod:`.requests`)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Annotated, Any, get_args

import typer

from ..constants import MAX_EVALS, MAX_IMAGE_SIDE, MAX_IMAGES, MAX_SEED
from ..perturb.registry import known
from .config import Config

__all__ = ["DEFAULT_IMAGES", "Address", "AllowUnmeasured", "Batch", "Clock", "Config", "Contrast", "Csv", "Design",
           "DetectorPlugin", "Device", "Engine", "Executor", "Frames", "Height", "Images", "Imgsz", "Landscape", "Lard", "Lipschitz", "MaxEvals",
           "MethodOption", "Methods", "Model", "Oracle", "OracleNoise", "Out", "Parquet", "Perturb", "PluginDigest",
           "Pnp", "Quiet", "Rate", "Report", "RetryFailed", "Roll", "Seed", "StoredRun", "Threads", "TrustModel", "Verbose",
           "Wait", "Width", "Workers", "variant"]


def variant(option: Any, annotation: Any = None, **changes: Any) -> Any:
    """``option`` (an ``Annotated`` option of this module) as one command words or bounds it: a copy of its
    declaration with ``changes`` (``help``, ``min``, ``max``, …) and, given ``annotation``, another value type
    (``int`` where the shared option admits ``None``). The option's name stays the shared one's."""
    kind, info = get_args(option)
    info = copy.copy(info)
    for name, value in changes.items():
        if not hasattr(info, name):
            raise TypeError(f"variant: a typer option has no attribute {name!r}")
        setattr(info, name, value)
    return Annotated[annotation if annotation is not None else kind, info]


#: Images of an audit or a risk run when ``--n`` is not given (all rows of a smaller ``--lard`` dataset).
DEFAULT_IMAGES = 20

# -- every campaign: what it prints and where ---------------------------------------------------------------
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or tables (also accepted before the "
                                     "command: vbl-robust -q COMMAND).")]
Verbose = Annotated[bool, typer.Option("--verbose", "-v", help="Log progress details (INFO) (also accepted before the "
                                       "command: vbl-robust -v COMMAND).")]
Out = Annotated[Path, typer.Option("--out", help="Run directory (results.sqlite, report.html).")]
#: A stored run, read (report, zones).
StoredRun = Annotated[Path, typer.Argument(help="Run directory (holding results.sqlite) or the .sqlite file.")]

# -- the images ---------------------------------------------------------------------------------------------------
Images = Annotated[int | None, typer.Option("--n", "--images", min=1, max=MAX_IMAGES, show_default=False,
                                            help=f"Number of images (default {DEFAULT_IMAGES}, or all rows of a "
                                                 "smaller --lard dataset).")]
Seed = Annotated[int, typer.Option("--seed", min=0, max=MAX_SEED, help="Seed of the image choice and of the searches.")]
Lard = Annotated[Path | None, typer.Option("--lard", help="LARD V2 dataset directory (CSV + runway DB JSON) instead "
                                           "of generated synthetic approaches.")]
Width = Annotated[int, typer.Option("--width", min=16, max=MAX_IMAGE_SIDE, help=f"Synthetic image width (px, at most "
                                    f"{MAX_IMAGE_SIDE}).")]
Height = Annotated[int, typer.Option("--height", min=16, max=MAX_IMAGE_SIDE, help=f"Synthetic image height (px, at "
                                     f"most {MAX_IMAGE_SIDE}).")]

# -- the detector (vbl_robust.detect.shipped.DetectorSpec.from_choice) --------------------------------------------
Model = Annotated[Path | None, typer.Option("--model", help="Detector: a YOLO-pose .pt or .onnx file, 'default' for "
                                            "the shipped model, 'yolo26' for the shipped model's pass 1 with a "
                                            "YOLO26-pose crop network that gives each corner's σ (--monitor-sigma), "
                                            "or 'hardened' for the shipped model hardened by vbl-robust harden once "
                                            "installed (default: the shipped model once it is validated, else the "
                                            "oracle).")]
DetectorPlugin = Annotated[str | None, typer.Option(
    "--detector-plugin", help="Any detector: MODULE:FACTORY or path/to/file.py:FACTORY, a factory returning an object "
    "that satisfies the Detector protocol (how-to: a detector plug-in). It is imported and run: naming it here is "
    "your consent; from a --config file it needs --trust-model. Not with --model or --oracle.")]
PluginDigest = Annotated[str | None, typer.Option(
    "--plugin-digest", help="With --detector-plugin: the SHA-256 of the plug-in's weights, recorded in its identity "
    "(the plug-in's source file is hashed by vbl-robust itself).")]
TrustModel = Annotated[bool, typer.Option("--trust-model", help="Allow loading a .pt pickle from outside the package.")]
Design = Annotated[str, typer.Option("--detector", help="Detector design: auto (the shipped model's own; a user's "
                                     "model as one pass), single (one pass: the paper's pipeline) or twostage.")]
Engine = Annotated[str, typer.Option("--engine", help="Inference engine of the black-box path: auto (ONNX Runtime when "
                                     "installed), torch, onnxruntime or openvino — always fp32; the outputs stay "
                                     "within 1e-3 px of torch's, APGD stays on torch.")]
Device = Annotated[str, typer.Option("--device", help="Where the pipeline runs: cpu (default), cuda, cuda:N, or auto "
                                     "(CUDA when available). On a GPU the perturbation, views, detector and "
                                     "differentiable PnP run there; --engine auto then means torch.")]
Oracle = Annotated[bool, typer.Option("--oracle", help="Use the oracle detector (exact projected corners).")]
OracleNoise = Annotated[float, typer.Option("--oracle-noise", min=0.0, help="Oracle: fixed per-image corner noise "
                                            "(px).")]

# -- the perturbation box (BoxRequest) ----------------------------------------------------------------------------
Roll = Annotated[str, typer.Option("--roll", help="Roll range in degrees: '15' (= ±15) or 'lo,hi'; 'none' to omit.")]
Contrast = Annotated[str | None, typer.Option("--contrast", help="Contrast factor range 'lo,hi' (e.g. 0.7,1.4).")]
Perturb = Annotated[list[str] | None, typer.Option(
    "--perturb", help="Another perturbation family and its range, NAME=LO,HI (repeatable; a bare NAME takes its "
    f"plausible default range): {known()} (roll_deg here replaces --roll; contrast here or in --contrast, not both).")]

# -- the searches -------------------------------------------------------------------------------------------------
Methods = Annotated[str, typer.Option("--methods", help="Comma-separated search methods.")]
MaxEvals = Annotated[int | None, typer.Option("--max-evals", min=0, max=MAX_EVALS, help="Evaluations per image and "
                                              "method (0 = no evaluation cap: then give --max-seconds).")]
Pnp = Annotated[str, typer.Option("--pnp", help="PnP solver: ippe_lm, iterative, sqpnp, ippe.")]
Lipschitz = Annotated[str | None, typer.Option("--lipschitz", help="Lipschitz constant of the error (m per unit, one "
                                               "number or one per parameter): enables 'certified' verdicts.")]
Landscape = Annotated[bool | None, typer.Option(
    "--landscape/--no-landscape", help="Dense grid on the first image for the report's landscape figure (default: "
    "on; with --sequences off, as each grid point costs every frame of the first sequence).")]
MethodOption = Annotated[list[str] | None, typer.Option(
    "--method-option", help="A search method's option, METHOD.OPTION=VALUE (repeatable; VALUE read as YAML: 9, 0.5, "
    "true, [3, 5]), e.g. georobust-a.min_ratio=9 or georobust.alpha=3; recorded in the store and the job keys.")]

# -- approach sequences ------------------------------------------------------------------------------------------
Frames = Annotated[int | None, typer.Option("--frames", min=1, help="With --sequences N: frames per sequence "
                                            "(default 20).")]
Rate = Annotated[float | None, typer.Option("--rate", help="With --sequences: frame rate in Hz (generated sequences; "
                                            "LARD data without times; default 10).")]

# -- how a campaign runs ------------------------------------------------------------------------------------------
Executor = Annotated[str, typer.Option("--executor", help="local or ray.")]
Address = Annotated[str | None, typer.Option("--address", help="Ray cluster address (default: start a local Ray); "
                                             "checked before the run (10 s).")]
Workers = Annotated[int, typer.Option("--workers", help="Worker processes of a local run, one torch thread each "
                                      "(default 0: one per core, or $VBL_ROBUST_WORKERS); 1 runs in this process.")]
Clock = Annotated[str, typer.Option("--clock", help="Clock of time budgets: process (CPU seconds of the evaluating "
                                    "process, which other work on the machine does not move), wall, or auto (process "
                                    "on a CPU, wall on a GPU). Recorded with the results.")]
Wait = Annotated[bool, typer.Option("--wait", help="When another run is writing the same --out, wait for it to end "
                                    "instead of refusing.")]
RetryFailed = Annotated[bool, typer.Option("--retry-failed", help="Run the jobs stored as not measured again (e.g. "
                                           "after a missing image was restored); a plain rerun skips them.")]
AllowUnmeasured = Annotated[bool, typer.Option(
    "--allow-unmeasured", help="Accept jobs the tool could not measure (an image missing or unreadable, an exception "
    "in the tool or the detector): run past images that cannot be read instead of refusing the run, and exit 0. "
    "Such jobs never enter a rate either way and are listed in the report; without this flag a run with an "
    "unreadable image is refused before it starts, and any job not measured makes the command exit 1.")]

# -- what a campaign writes ---------------------------------------------------------------------------------------
Csv = Annotated[Path | None, typer.Option("--csv", help="Also export the job rows to this CSV file.")]
Parquet = Annotated[Path | None, typer.Option("--parquet", help="Also export the job rows to this Parquet file.")]
Report = Annotated[bool, typer.Option("--report/--no-report", help="Write report.html into --out.")]

# -- training (train, harden) -------------------------------------------------------------------------------------
Imgsz = Annotated[int, typer.Option("--imgsz", min=32, max=4096, help="Network input size (a multiple of 32, 32 to "
                                    "4096).")]
Batch = Annotated[int, typer.Option("--batch", min=1, help="Training batch size (views per optimizer step).")]
Threads = Annotated[int | None, typer.Option("--threads", min=1, help="Torch threads for CPU training (default: all "
                                             "cores).")]
