"""``vbl-robust train``: train (or keep training) the runway-corner YOLOv8n-pose, offline, resumable;
``vbl-robust ship``: make a trained checkpoint the default model when the protocol's rule allows it;
``vbl-robust harden``: fine-tune a detector on the worst of k perturbed views per image."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path
from typing import Annotated

import typer

from ..consent import DetectorKind, refuse_untrusted
from ..constants import MAX_IMAGES
from ..space import ParameterBox
from . import options as o
from .common import fail, one_line, parse_perturb

# -- train's own options ------------------------------------------------------------------------------------------
TrainOut = o.variant(o.Out, help="Working directory (dataset + stages).")
Resume = Annotated[bool, typer.Option("--resume", help="Continue the latest stage, or start a new stage from its best "
                                      "weights.")]
TrainLard = o.variant(o.Lard, help="Train on a LARD V2 directory (CSV + runway DB JSON) instead of synthetic scenes.")
TrainNTrain = Annotated[int, typer.Option("--n-train", min=2, max=MAX_IMAGES, help="Synthetic training approaches.")]
TrainNVal = Annotated[int, typer.Option("--n-val", min=1, max=MAX_IMAGES, help="Validation approaches.")]
Airports = Annotated[int | None, typer.Option("--airports", min=1, help="Synthetic airports (runway sizes) of the "
                                              "generated data (default: the generator's pool).")]
TrainEpochs = Annotated[int, typer.Option("--epochs", min=1, help="Epochs of this stage.")]
TrainSeed = o.variant(o.Seed, max=None, help="Seed of the rendered samples, the crops and the training.")
TrainDesign = o.variant(o.Design, help="'twostage' (full view + runway crop) or 'single'.")
Init = Annotated[str | None, typer.Option("--init", help="Initial weights of a first stage: a .pt path or 'default' "
                                          "(the shipped model).")]
TrainTrust = o.variant(o.TrustModel, help="Allow loading an --init .pt pickle from outside the package, and (--resume) "
                       "the checkpoints of --out.")
Crops = Annotated[int, typer.Option("--crops", min=0, help="Jittered runway crops rendered per training sample "
                                    "(two-stage).")]
CropsUsed = Annotated[int | None, typer.Option("--crops-used", min=0, help="Train on only the first N crops of each "
                                               "sample (more weight on full views).")]
MinBox = Annotated[float | None, typer.Option("--min-box", min=0, help="Minimum labelled box side in view pixels "
                                              "(default 7.5 % of --imgsz).")]
Lr0 = Annotated[float | None, typer.Option("--lr0", help="Initial learning rate (default: ultralytics').")]
Optimizer = Annotated[str, typer.Option("--optimizer", help="Ultralytics optimizer: auto, SGD, AdamW, ...")]
LoaderWorkers = Annotated[int, typer.Option("--workers", min=0, help="Data-loader worker processes.")]
CropsOnly = Annotated[bool, typer.Option("--crops-only", help="Train on the crops alone (a pass-2 network of its own; "
                                         "full views still rendered and validated).")]
Arch = Annotated[str, typer.Option("--arch", help="Network of a first stage trained from scratch: yolov8n-pose (every "
                                   "shipped model so far) or yolo26n-pose (YOLO26: residual log-likelihood keypoints); "
                                   "ignored with --init or --resume.")]
Appearance = Annotated[bool, typer.Option("--appearance", help="Random blur, haze, contrast, brightness, gamma and "
                                          "sensor noise on half of the training images (vbl_robust.detect.augment; "
                                          "validation untouched).")]


def train(
    out: TrainOut = Path("train_runs/default"), resume: Resume = False, lard: TrainLard = None,
    n_train: TrainNTrain = 1000, n_val: TrainNVal = 100, airports: Airports = None, imgsz: o.Imgsz = 320,
    epochs: TrainEpochs = 10, batch: o.Batch = 16, seed: TrainSeed = 0, detector: TrainDesign = "twostage",
    init: Init = None, trust_model: TrainTrust = False, crops: Crops = 2, crops_used: CropsUsed = None,
    min_box: MinBox = None, lr0: Lr0 = None, optimizer: Optimizer = "auto", workers: LoaderWorkers = 2,
    threads: o.Threads = None, crops_only: CropsOnly = False, appearance: Appearance = False,
    arch: Arch = "yolov8n-pose",
) -> None:
    """Train the default detector from our synthetic scenes (or your LARD V2 data); every call adds a stage."""
    from vbl_robust.detect import train as tr
    from vbl_robust.scenes.airports import DEFAULT_POOL

    if lr0 is not None and not (math.isfinite(lr0) and lr0 > 0):  # before the working directory is made
        fail(f"--lr0 {lr0}: a learning rate must be a finite number > 0")
    init_path = None if init is None else _weights(init, trust_model, "--init")
    samples = None
    if lard is not None:
        from vbl_robust.campaigns.samples import find_lard_files  # torch behind it: not for ``--help``
        from vbl_robust.data.lard_read import read_lard

        with one_line():
            csv_path, db_path = find_lard_files(lard)
            samples = read_lard(csv_path, db_path, corners_in_image=True)
    with one_line():
        res = tr.train(out, samples=samples, n_train=n_train, n_val=n_val, imgsz=imgsz, epochs=epochs,
                       batch=batch, seed=seed, resume=resume, trust_checkpoints=trust_model,
                       init_weights=init_path, detector=detector,
                       crops_per_sample=crops, crops_used=crops_used, min_box=min_box, lr0=lr0,
                       optimizer=optimizer, workers=workers, threads=threads,
                       n_airports=airports or DEFAULT_POOL,
                       appearance=tr.AppearanceJitter() if appearance else None, full_views=not crops_only,
                       architecture=arch)
    typer.echo(f"stage {res.stage_dir.name}: best weights {res.best} (measure it with "
               "benchmarks/detector_protocol.py --model ... --json P.json, then vbl-robust ship)")


def _weights(model: str | Path, trust: bool, option: str) -> Path:
    """The weights a training starts from: a shipped model's name or a user's ``.pt`` (refused unless trusted), read
    as every command reads a model (:meth:`~vbl_robust.detect.shipped.DetectorSpec.from_choice`)."""
    from vbl_robust.detect.shipped import DetectorSpec, default_model_status

    with one_line():
        spec = DetectorSpec.from_choice(model, trust=trust, option=option)
    if spec.kind not in (DetectorKind.DEFAULT, DetectorKind.ULTRALYTICS):
        fail(f"{option} {model}: training starts from a .pt file")
    if spec.model_file is None:
        fail(f"{option} {model}: {default_model_status(spec.shipped_name)}")
    if not zipfile.is_zipfile(spec.model_file):  # checked here: ultralytics would fail mid-set-up with a traceback
        fail(f"{option} {model}: not a PyTorch checkpoint (torch.save writes a zip archive; this file of "
             f"{spec.model_file.stat().st_size} bytes is not one)")
    return spec.model_file


# -- ship's own options -------------------------------------------------------------------------------------------
Checkpoint = Annotated[Path, typer.Argument(help="The trained weights (.pt) to ship.")]
Version = Annotated[int, typer.Option("--version", min=1, help="The model's version number (default.json).")]
ShipEpochs = Annotated[int, typer.Option("--epochs", min=0, help="Epochs the model was trained in all (default.json).")]
Protocol = Annotated[Path, typer.Option("--protocol", help="The checkpoint's protocol JSON (benchmarks/"
                                        "detector_protocol.py --split all --json): default.json's note, gate and open "
                                        "goals are computed from it.")]
Against = Annotated[Path | None, typer.Option("--against", help="The shipped model's protocol JSON: the replacement "
                                              "rule (more pooled validation approaches survive, exact McNemar p < "
                                              "0.05) is checked before anything is written.")]
Force = Annotated[bool, typer.Option("--force", help="Ship even without --against or when the rule is not met (a first "
                                     "model, or a rule set aside on purpose: say why in the model card).")]
ShipTrust = o.variant(o.TrustModel, help="The checkpoint is a pickle: confirm you trust it.")
As = Annotated[str, typer.Option("--as", help="Which shipped model it becomes: default (the replacement rule applies) "
                                 "or hardened (shipped beside the default, replacing none; --against then only prints "
                                 "the paired comparison).")]


def ship(
    checkpoint: Checkpoint, version: Version, epochs: ShipEpochs, protocol: Protocol, against: Against = None,
    force: Force = False, trust_model: ShipTrust = False, name: As = "default",
) -> None:
    """Ship a trained checkpoint as a shipped detector (two-stage, 320 px): the default, or with --as hardened
    beside it; its default.json from the checkpoint's protocol."""
    from vbl_robust.detect.protocol import info_from_protocol, replacement_verdict
    from vbl_robust.detect.shipped import SHIPPED_MODELS, shipped_model_dir

    if name not in SHIPPED_MODELS:
        fail(f"--as {name}: shipped models are {', '.join(SHIPPED_MODELS)}")
    replaces = name == "default"
    if not checkpoint.is_file():
        fail(f"{checkpoint}: file not found")
    with one_line(ValueError):
        refuse_untrusted(checkpoint, trust_model)
    with one_line(OSError, ValueError, prefix="--protocol/--against: "):
        result = json.loads(protocol.read_text())
        shipped = json.loads(against.read_text()) if against is not None else None
    if shipped is None and replaces and not force:
        fail("--against SHIPPED.json is required (the replacement rule); --force skips it")
    if shipped is not None:
        ok, why = replacement_verdict(result, shipped)
        typer.echo(f"replacement rule {'met' if ok else 'NOT met'}: {why}" if replaces else f"against it: {why}")
        if not ok and replaces and not force:
            fail("not shipped: the candidate cannot be told from the shipped model (--force ships anyway)")
    with one_line(KeyError, StopIteration, prefix=f"--protocol {protocol}: not a complete protocol result "
                  "(benchmarks/detector_protocol.py --split all --json): missing "):
        info = info_from_protocol(result, version, epochs)
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.train import ship as ship_weights

    setup_offline()
    typer.echo(json.dumps(info, indent=1))
    with one_line():
        shipped_to = ship_weights(checkpoint, detector="twostage", imgsz=320, info=info,
                                  models_dir=shipped_model_dir(name))
    typer.echo(f"shipped {shipped_to}")


# -- harden's own options -----------------------------------------------------------------------------------------
HardenPerturb = o.variant(o.Perturb, list[str], help="A perturbation family and its range, NAME=LO,HI (repeatable; a "
                          "bare NAME takes its plausible default range): the box the training views are drawn from.")
HardenOut = o.variant(o.Out, help="Working directory (one roundNN per round).")
HardenModel = o.variant(o.Model, help="The .pt to harden, or a shipped model's name (default, hardened; default: the "
                        "shipped default model).")
HardenTrust = o.variant(o.TrustModel, help="Allow loading a --model .pt pickle from outside the package.")
Rounds = Annotated[int, typer.Option("--rounds", min=1, max=100, help="Rounds: search the worst views, then fine-tune "
                                     "(at most 100).")]
K = Annotated[int, typer.Option("--k", min=1, max=10_000, help="Candidates per training image and round (worst of k, "
                                "at most 10000).")]
HardenEpochs = o.variant(TrainEpochs, help="Epochs per round.")
HardenNTrain = o.variant(TrainNTrain, min=1)
HardenNVal = o.variant(TrainNVal, help="Synthetic validation approaches (clean).")
HardenSeed = o.variant(o.Seed, int | None, max=None, help="Seed of the training approaches (their own airports), the "
                       "candidates and the training (default: detect.protocol.HARDEN_SEED); the audits' seed 0 and the "
                       "protocol's validation and test seeds are refused.")
Clean = Annotated[bool, typer.Option("--clean/--no-clean", help="Train on the clean images too (half the views).")]
Data = Annotated[str, typer.Option(
    "--data", help="Which synthetic approaches: audit (the generator's defaults, as the audits draw them) or shipped "
    "(the shipped model's own training mix: three far approaches for each medium and close one, 2000 airports; "
    "detect.train.SHIPPED_DATA).")]


def harden(
    perturb: HardenPerturb, out: HardenOut = Path("train_runs/harden"), model: HardenModel = None,
    trust_model: HardenTrust = False, rounds: Rounds = 2, k: K = 8, epochs: HardenEpochs = 2,
    n_train: HardenNTrain = 300, n_val: HardenNVal = 60, seed: HardenSeed = None, clean: Clean = True,
    data: Data = "audit", imgsz: o.Imgsz = 320, batch: o.Batch = 16, threads: o.Threads = None,
    engine: o.Engine = "torch", device: o.Device = "cpu",
) -> None:
    """Fine-tune a detector on the worst of k perturbed views per image, scored by the audit's error (rounds)."""
    from vbl_robust.campaigns.harden import harden as run_harden
    from vbl_robust.detect.protocol import HARDEN_FORBIDDEN_SEEDS, HARDEN_SEED
    from vbl_robust.detect.train import SHIPPED_DATA, VAL_SEED_OFFSET
    from vbl_robust.scenes.generate import generate

    scenes = {"audit": {}, "shipped": SHIPPED_DATA}
    if data not in scenes:
        fail(f"--data {data}: choose {' or '.join(scenes)}")
    seed = HARDEN_SEED if seed is None else seed
    if seed in HARDEN_FORBIDDEN_SEEDS:
        fail(f"--seed {seed}: the approaches of this seed are an audit's or the detector protocol's (never trained "
             f"on); choose another (default {HARDEN_SEED})")
    weights = None if model is None else _weights(model, trust_model, "--model")
    with one_line():
        box = ParameterBox(parse_perturb(perturb))
        rs = run_harden(out, box, train_samples=generate(n_train, seed=seed, **scenes[data]),
                        val_samples=generate(n_val, seed=seed + VAL_SEED_OFFSET, **scenes[data]), init_weights=weights,
                        rounds=rounds, k=k, epochs=epochs, seed=seed, imgsz=imgsz, batch=batch, threads=threads,
                        clean=clean, engine=engine, device=device,
                        trust_rounds=trust_model)  # the user's word on the .pt files of --out
    for r in rs:
        took = "" if r.train_s is None else f" (search {r.search_s:.0f} s, training {r.train_s:.0f} s)"
        typer.echo(f"round {r.index}: {r.breaches} of {len(r.worst)} training images breached by their worst "
                   f"view; weights {r.weights}{took}")
