"""``vbl-robust train``: train (or keep training) the runway-corner YOLOv8n-pose, offline, resumable;
``vbl-robust ship``: make a trained checkpoint the default model when the protocol's rule allows it."""

from __future__ import annotations

from pathlib import Path

import typer

from ..constants import MAX_IMAGES
from .common import fail


def register(app: typer.Typer) -> None:
    @app.command()
    def train(
        out: Path = typer.Option(Path("train_runs/default"), "--out", help="Working directory (dataset + stages)."),
        resume: bool = typer.Option(False, "--resume", help="Continue the latest stage, or start a new stage from its best weights."),
        lard: Path = typer.Option(None, "--lard", help="Train on a LARD V2 directory (CSV + runway DB JSON) instead of synthetic scenes."),
        n_train: int = typer.Option(1000, "--n-train", min=2, max=MAX_IMAGES, help="Synthetic training approaches."),
        n_val: int = typer.Option(100, "--n-val", min=1, max=MAX_IMAGES, help="Validation approaches."),
        airports: int = typer.Option(None, "--airports", min=1, help="Synthetic airports (runway sizes) of the generated data (default: the generator's pool)."),
        imgsz: int = typer.Option(320, "--imgsz", min=32, max=4096, help="Network input size (a multiple of 32, 32 to 4096)."),
        epochs: int = typer.Option(10, "--epochs", min=1, help="Epochs of this stage."),
        batch: int = typer.Option(16, "--batch", min=1, help="Training batch size (views per optimizer step)."),
        seed: int = typer.Option(0, "--seed", min=0, help="Seed of the rendered samples, the crops and the training."),
        detector: str = typer.Option("twostage", "--detector", help="'twostage' (full view + runway crop) or 'single'."),
        init: str = typer.Option(None, "--init", help="Initial weights of a first stage: a .pt path or 'default' (the shipped model)."),
        trust_model: bool = typer.Option(False, "--trust-model", help="Allow loading an --init .pt pickle from outside the package, and (--resume) the checkpoints of --out."),
        crops: int = typer.Option(2, "--crops", min=0, help="Jittered runway crops rendered per training sample (two-stage)."),
        crops_used: int = typer.Option(None, "--crops-used", min=0, help="Train on only the first N crops of each sample (more weight on full views)."),
        min_box: float = typer.Option(None, "--min-box", min=0, help="Minimum labelled box side in view pixels (default 7.5 % of --imgsz)."),
        lr0: float = typer.Option(None, "--lr0", help="Initial learning rate (default: ultralytics')."),
        optimizer: str = typer.Option("auto", "--optimizer", help="Ultralytics optimizer: auto, SGD, AdamW, ..."),
        workers: int = typer.Option(2, "--workers", min=0, help="Data-loader worker processes."),
        threads: int = typer.Option(None, "--threads", min=1, help="Torch threads for CPU training (default: all cores)."),
        crops_only: bool = typer.Option(False, "--crops-only", help="Train on the crops alone (a pass-2 network of its own; full views still rendered and validated)."),
        appearance: bool = typer.Option(False, "--appearance", help="Random blur, haze, contrast, brightness, gamma and sensor noise on half of the training images (vbl_robust.detect.augment; validation untouched)."),
    ) -> None:
        """Train the default detector from our synthetic scenes (or your LARD V2 data); every call adds a stage."""
        from vbl_robust.detect import train as tr
        from vbl_robust.detect.shipped import DEFAULT_MODEL
        from vbl_robust.scenes.airports import DEFAULT_POOL

        init_path = None
        if init == "default":
            init_path = DEFAULT_MODEL
        elif init is not None:
            init_path = Path(init)
            if not init_path.is_file():
                fail(f"--init {init_path}: file not found")
            if not trust_model:
                fail(f"--init {init_path}: a .pt file is a pickle that runs code when loaded; pass --trust-model if you trust it")
        samples = None
        if lard is not None:
            from vbl_robust.campaigns.samples import find_lard_files
            from vbl_robust.data import read_lard

            try:
                csv_path, db_path = find_lard_files(lard)
                samples = read_lard(csv_path, db_path, corners_in_image=True)
            except (ValueError, FileNotFoundError) as exc:
                fail(str(exc))
        try:
            res = tr.train(out, samples=samples, n_train=n_train, n_val=n_val, imgsz=imgsz, epochs=epochs,
                           batch=batch, seed=seed, resume=resume, trust_checkpoints=trust_model,
                           init_weights=init_path, detector=detector,
                           crops_per_sample=crops, crops_used=crops_used, min_box=min_box, lr0=lr0,
                           optimizer=optimizer, workers=workers, threads=threads,
                           n_airports=airports or DEFAULT_POOL,
                           appearance=tr.AppearanceJitter() if appearance else None, full_views=not crops_only)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        typer.echo(f"stage {res.stage_dir.name}: best weights {res.best} (measure it with "
                   "benchmarks/detector_protocol.py --model ... --json P.json, then vbl-robust ship)")

    @app.command()
    def ship(
        checkpoint: Path = typer.Argument(..., help="The trained weights (.pt) to ship."),
        version: int = typer.Option(..., "--version", min=1, help="The model's version number (default.json)."),
        epochs: int = typer.Option(..., "--epochs", min=0, help="Epochs the model was trained in all (default.json)."),
        protocol: Path = typer.Option(..., "--protocol", help="The checkpoint's protocol JSON (benchmarks/"
                                      "detector_protocol.py --split all --json): default.json's note, gate and open "
                                      "goals are computed from it."),
        against: Path | None = typer.Option(None, "--against", help="The shipped model's protocol JSON: the "
                                            "replacement rule (more pooled validation approaches survive, exact "
                                            "McNemar p < 0.05) is checked before anything is written."),
        force: bool = typer.Option(False, "--force", help="Ship even without --against or when the rule is not met "
                                   "(a first model, or a rule set aside on purpose: say why in the model card)."),
        trust_model: bool = typer.Option(False, "--trust-model", help="The checkpoint is a pickle: confirm you trust it."),
        name: str = typer.Option("default", "--as", help="Which shipped model it becomes: default (the replacement "
                                 "rule applies) or hardened (shipped beside the default, replacing none; --against "
                                 "then only prints the paired comparison)."),
    ) -> None:
        """Ship a trained checkpoint as a shipped detector (two-stage, 320 px): the default, or with --as hardened
        beside it; its default.json from the checkpoint's protocol."""
        import json

        from vbl_robust.detect.protocol import info_from_protocol, replacement_verdict
        from vbl_robust.detect.shipped import SHIPPED_MODELS, shipped_model_dir

        if name not in SHIPPED_MODELS:
            fail(f"--as {name}: shipped models are {', '.join(SHIPPED_MODELS)}")
        replaces = name == "default"

        if not checkpoint.is_file():
            fail(f"{checkpoint}: file not found")
        if not trust_model:
            fail(f"{checkpoint}: a .pt file is a pickle that runs code when loaded; pass --trust-model if you trust it")
        try:
            result = json.loads(protocol.read_text())
            shipped = json.loads(against.read_text()) if against is not None else None
        except (OSError, ValueError) as exc:
            fail(f"--protocol/--against: {exc}")
        if shipped is None and replaces and not force:
            fail("--against SHIPPED.json is required (the replacement rule); --force skips it")
        if shipped is not None:
            ok, why = replacement_verdict(result, shipped)
            typer.echo(f"replacement rule {'met' if ok else 'NOT met'}: {why}" if replaces else f"against it: {why}")
            if not ok and replaces and not force:
                fail("not shipped: the candidate cannot be told from the shipped model (--force ships anyway)")
        try:
            info = info_from_protocol(result, version, epochs)
        except (KeyError, StopIteration) as exc:
            fail(f"--protocol {protocol}: not a complete protocol result (benchmarks/detector_protocol.py --split all "
                 f"--json): missing {exc}")
        from vbl_robust.detect.offline import setup_offline
        from vbl_robust.detect.train import ship as ship_weights

        setup_offline()
        typer.echo(json.dumps(info, indent=1))
        try:
            shipped_to = ship_weights(checkpoint, detector="twostage", imgsz=320, info=info,
                                      models_dir=shipped_model_dir(name))
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        typer.echo(f"shipped {shipped_to}")

    @app.command()
    def harden(
        perturb: list[str] = typer.Option(..., "--perturb", help="A perturbation family and its range, NAME=LO,HI "
                                          "(repeatable; a bare NAME takes its plausible default range): the box "
                                          "the training views are drawn from."),
        out: Path = typer.Option(Path("train_runs/harden"), "--out", help="Working directory (one roundNN per round)."),
        model: Path | None = typer.Option(None, "--model", help="The .pt to harden, or a shipped model's name "
                                          "(default, hardened; default: the shipped default model)."),
        trust_model: bool = typer.Option(False, "--trust-model", help="Allow loading a --model .pt pickle from "
                                         "outside the package."),
        rounds: int = typer.Option(2, "--rounds", min=1, max=100, help="Rounds: search the worst views, then fine-tune (at most 100)."),
        k: int = typer.Option(8, "--k", min=1, max=10_000, help="Candidates per training image and round (worst of k, at most 10000)."),
        epochs: int = typer.Option(2, "--epochs", min=1, help="Epochs per round."),
        n_train: int = typer.Option(300, "--n-train", min=1, max=MAX_IMAGES, help="Synthetic training approaches."),
        n_val: int = typer.Option(60, "--n-val", min=1, max=MAX_IMAGES, help="Synthetic validation approaches (clean)."),
        seed: int | None = typer.Option(None, "--seed", min=0, help="Seed of the training approaches (their own airports), "
                                        "the candidates and the training (default: detect.protocol.HARDEN_SEED); the "
                                        "audits' seed 0 and the protocol's validation and test seeds are refused."),
        clean: bool = typer.Option(True, "--clean/--no-clean", help="Train on the clean images too (half the views)."),
        data: str = typer.Option("audit", "--data", help="Which synthetic approaches: audit (the generator's defaults, "
                                 "as the audits draw them) or shipped (the shipped model's own training mix: three far "
                                 "approaches for each medium and close one, 2000 airports; detect.train.SHIPPED_DATA)."),
        imgsz: int = typer.Option(320, "--imgsz", min=32, max=4096, help="Network input size (a multiple of 32, 32 to 4096)."),
        batch: int = typer.Option(16, "--batch", min=1, help="Training batch size (views per optimizer step)."),
        threads: int = typer.Option(None, "--threads", min=1, help="Torch threads for CPU training (default: all cores)."),
    ) -> None:
        """Fine-tune a detector on the worst of k perturbed views per image, scored by the audit's error (rounds)."""
        from vbl_robust.detect.harden import harden as run_harden
        from vbl_robust.detect.protocol import HARDEN_FORBIDDEN_SEEDS, HARDEN_SEED
        from vbl_robust.detect.shipped import SHIPPED_MODELS, default_model_path, default_model_status
        from vbl_robust.detect.train import SHIPPED_DATA, VAL_SEED_OFFSET
        from vbl_robust.scenes import generate
        from vbl_robust.space import ParameterBox

        from .audit import parse_perturb

        scenes = {"audit": {}, "shipped": SHIPPED_DATA}
        if data not in scenes:
            fail(f"--data {data}: choose {' or '.join(scenes)}")
        seed = HARDEN_SEED if seed is None else seed
        if seed in HARDEN_FORBIDDEN_SEEDS:
            fail(f"--seed {seed}: the approaches of this seed are an audit's or the detector protocol's (never trained "
                 f"on); choose another (default {HARDEN_SEED})")
        trust_rounds = trust_model  # the user's word on the .pt files of --out (before a shipped model sets it)
        if model is not None and str(model) in SHIPPED_MODELS:  # a shipped model: part of the package, trusted
            name = str(model)
            model = default_model_path(name)
            if model is None:
                fail(f"--model {name}: {default_model_status(name)}")
            trust_model = True
        if model is not None and not model.is_file():
            fail(f"--model {model}: file not found")
        if model is not None and not trust_model:
            fail(f"--model {model}: a .pt file is a pickle that runs code when loaded; pass --trust-model if you trust it")
        try:
            box = ParameterBox(parse_perturb(perturb))
            rs = run_harden(out, box, train_samples=generate(n_train, seed=seed, **scenes[data]),
                            val_samples=generate(n_val, seed=seed + VAL_SEED_OFFSET, **scenes[data]), init_weights=model,
                            rounds=rounds, k=k, epochs=epochs, seed=seed, imgsz=imgsz, batch=batch, threads=threads,
                            clean=clean, trust_rounds=trust_rounds)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        for r in rs:
            took = "" if r.train_s is None else f" (search {r.search_s:.0f} s, training {r.train_s:.0f} s)"
            typer.echo(f"round {r.index}: {r.breaches} of {len(r.worst)} training images breached by their worst "
                       f"view; weights {r.weights}{took}")
