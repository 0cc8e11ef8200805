"""Train the runway-corner keypoint model (YOLOv8n-pose) with ultralytics, offline, resumable and cumulative.

Data: each :class:`~vbl_robust.data.sample.Sample` gives square *views* (see :mod:`vbl_robust.perturb.views`), rendered
at the training size with the same resampling the detectors use at inference:

- the letterboxed full image (what a single-pass detector, or the first pass of the two-stage one, sees);
- for the two-stage design, ``crops_per_sample`` crops around the runway's corner box, jittered in centre and
  size the way a first-pass box is wrong (what the second pass sees).

One network learns both (the two passes share the weights), so one training run serves ``detector="single"``
and ``detector="twostage"``. Labels follow :mod:`vbl_robust.data.yolo` (half-pixel convention handled there).

Runs: every call of :func:`train` is a *stage* ``out_dir/stageNN``. ``resume=True`` continues an interrupted
stage from its ``last.pt``; when the latest stage is finished, it starts a new stage initialised from that
stage's ``best.pt`` — hours of training accumulate over several calls. Augmentation keeps corners exact: no
vertical flip, horizontal flip with ``flip_idx``, translation only (no mosaic, scale, rotation or shear: the crop
jitter provides position and scale diversity, and ultralytics' affine warps are not half-pixel exact).
Optionally (``appearance``) the training images get random blur, haze, photometric and sensor-noise changes
before their views are cut (:mod:`vbl_robust.detect.augment`: the perturbation families' own maths).
Labelled boxes are widened to ``min_box`` view pixels (keypoints unchanged) so that far runways, a few pixels
wide in the full view, get positive anchors; CPU training uses every core (``threads``).
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..atomic import atomic_write
from ..data.sample import Sample
from ..data.yolo import write_data_yaml, write_pose_images
from ..perturb.views import image_to_view, resample, to_tensor
from ..scenes.airports import DEFAULT_POOL
from .augment import AppearanceJitter
from .losses import threshold_width_loss
from .offline import import_ultralytics
from .windows import box_window, letterbox_window

logger = logging.getLogger(__name__)

#: ultralytics overrides that keep labels exact and the run offline
#: Networks a first stage can be trained from (ultralytics model files, built offline from their .yaml).
ARCHITECTURES = ("yolov8n-pose", "yolo26n-pose")

TRAIN_DEFAULTS = dict(
    mosaic=0.0, mixup=0.0, copy_paste=0.0, degrees=0.0, shear=0.0, perspective=0.0, scale=0.0,
    translate=0.1, fliplr=0.5, flipud=0.0, hsv_h=0.015, hsv_s=0.5, hsv_v=0.4, erasing=0.0,
    amp=False, plots=False, val=True, cache=False, device="cpu", verbose=False, deterministic=True,
    close_mosaic=0, warmup_epochs=1.0, patience=1000,
)


#: default minimum side of a labelled box, as a fraction of the training size (24 px at 320: three stride-8 anchors)
MIN_BOX_FRACTION = 0.075

#: synthetic validation samples come from ``generate(n_val, seed + VAL_SEED_OFFSET)``
VAL_SEED_OFFSET = 1_000_003

#: The recipe of the shipped model's last training steps (training log Q and R → v9, ``models/MODEL_CARD.md``):
#: AdamW, learning rate 1e-4 → 1e-5 cosine after a tenth of an epoch's warm-up, labelled boxes ≥ 24 px, keypoint
#: gain 36, threshold-width loss 0.5, appearance jitter, one crop per view. A fine-tune of that model
#: (``vbl-robust harden``) keeps it, so that what changes in the model is the fine-tune's data, not a new recipe
#: (ultralytics' own defaults — another optimizer, a higher rate, keypoint gain 12 — would retrain it).
FINE_TUNE = dict(optimizer="AdamW", lr0=1e-4, lrf=0.1, cos_lr=True, warmup_epochs=0.1, min_box=24.0, pose=36.0,
                 width_loss=0.5, appearance={}, crops_per_sample=1, workers=0)

#: The synthetic data of the shipped model's last training steps (training log K–R → v9, ``tools/train_step.py``):
#: three far approaches for each medium and each close one, runways 1500–4500 m long, a pool of 2000 airports
#: (``scenes.generate`` keyword arguments). ``vbl-robust harden --data shipped`` draws its approaches from it, so
#: that a fine-tune does not also move the model to another mix of envelopes and airports.
SHIPPED_DATA = dict(weights=(3.0, 1.0, 1.0), runway_length_range_m=(1500.0, 4500.0), n_airports=2000)


@dataclass
class CropJitter:
    """How training crops are drawn around the true corner box (see :func:`~vbl_robust.detect.windows.box_window`).

    margin/min_side: nominal window; shift: centre shift, uniform in ± shift·side per axis; scale: side factor,
    log-uniform in [1/scale, scale].
    """

    margin: float = 1.5
    min_side: float = 64.0
    shift: float = 0.12
    scale: float = 1.25


def corner_box_edge(corners_2d: np.ndarray) -> np.ndarray:
    """(4,) xyxy bounding box in edge coordinates of (4, 2) OpenCV-pixel corners."""
    e = np.asarray(corners_2d, dtype=np.float64) + 0.5
    return np.concatenate([e.min(0), e.max(0)])


def sample_views(
    sample: Sample, imgsz: int, *, crops: int, rng: np.random.Generator, jitter: CropJitter | None = None,
    full: bool = True, appearance: AppearanceJitter | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Render the training views of one sample: ``[(image (imgsz, imgsz, 3) uint8, corners (4, 2) view px)]``.

    ``appearance``: a random appearance change of the source image before the views are cut
    (:class:`~vbl_robust.detect.augment.AppearanceJitter`; its own stream, drawn from ``rng`` after the crop
    windows, so the windows are the same with and without it)."""
    jitter = jitter or CropJitter()
    wins = []
    if full:
        wins.append(letterbox_window(sample.height, sample.width))
    if crops:
        box = torch.as_tensor(corner_box_edge(sample.corners_2d))[None]
        base = box_window(box, margin=jitter.margin, min_side=jitter.min_side,
                          max_side=2.0 * max(sample.width, sample.height))[0].numpy()
        for _ in range(crops):
            side = base[2] * float(np.exp(rng.uniform(-np.log(jitter.scale), np.log(jitter.scale))))
            c = base[:2] + base[2] / 2 + rng.uniform(-jitter.shift, jitter.shift, 2) * side
            wins.append((float(c[0] - side / 2), float(c[1] - side / 2), float(side)))
    if not wins:
        return []
    img = to_tensor(sample.image)
    if appearance is not None:
        img, _ = appearance.apply(img, np.random.default_rng(int(rng.integers(0, 2**63))))
    img = img.expand(len(wins), -1, -1, -1)
    views = resample(img, torch.tensor(wins, dtype=torch.float32), imgsz)
    arr = (views.clamp(0, 1) * 255.0).round().to(torch.uint8).permute(0, 2, 3, 1).numpy()
    return [(arr[i], image_to_view(sample.corners_2d, w, imgsz)) for i, w in enumerate(wins)]


def build_dataset(
    train_samples: Sequence[Sample], val_samples: Sequence[Sample], root: str | Path, *, imgsz: int = 320,
    crops_per_sample: int = 2, seed: int = 0, jitter: CropJitter | None = None, min_box: float = 0.0,
    appearance: AppearanceJitter | None = None,
) -> Path:
    """Render and write a YOLO-pose dataset; returns the path of its ``data.yaml``.

    Sample ``i`` of a split gives the files ``{i:06d}_{j}`` (view ``j``; crop jitter from the seed stream
    ``(seed, split, i)``), so the build is incremental: a sample whose views all exist is not rendered again
    (a growing prefix-stable sample list, such as ``scenes.generate(n, seed)``, only renders the new samples).
    Validation gets one full view and (if ``crops_per_sample > 0``) one jittered crop per sample. Extra files
    beyond the requested sizes are removed, so the directory always matches the arguments. ``min_box``: minimum
    side of the labelled boxes in view pixels (:func:`~vbl_robust.data.yolo.pose_label`). ``appearance``:
    random appearance changes of the training samples' images (never of validation's), recorded in the build.
    """
    root = Path(root).resolve()
    spec = dict(imgsz=imgsz, crops=crops_per_sample, seed=seed, jitter=(jitter or CropJitter()).__dict__,
                min_box=float(min_box))
    if appearance is not None:  # only when given: datasets built before it existed keep their marker
        spec["appearance"] = appearance.to_dict()
    marker = root / "build.json"
    if marker.exists() and json.loads(marker.read_text()) != spec:
        raise ValueError(f"build_dataset: {root} was built with {marker.read_text()}, now {spec}; "
                         "use another directory")
    root.mkdir(parents=True, exist_ok=True)
    marker.write_text(json.dumps(spec))
    for k, (split, samples, crops) in enumerate((("train", train_samples, crops_per_sample),
                                                  ("val", val_samples, min(crops_per_sample, 1)))):
        nviews = 1 + crops
        img_dir, lbl_dir = root / "images" / split, root / "labels" / split

        def items(samples=samples, crops=crops, nviews=nviews, img_dir=img_dir, k=k, split=split):
            for i, s in enumerate(samples):
                if all((img_dir / f"{i:06d}_{j}.png").exists() for j in range(nviews)):
                    continue
                rng = np.random.default_rng([seed, k, i])
                app = appearance if split == "train" else None
                for j, (img, c) in enumerate(sample_views(s, imgsz, crops=crops, rng=rng, jitter=jitter,
                                                          appearance=app)):
                    yield f"{i:06d}_{j}", img, c
                s.drop_pixels()

        n = write_pose_images(items(), root, split, min_box=min_box)
        keep = {f"{i:06d}_{j}" for i in range(len(samples)) for j in range(nviews)}
        for d in (img_dir, lbl_dir):
            for f in d.glob("*"):
                if f.suffix in (".png", ".txt") and f.stem not in keep:
                    f.unlink()
        (lbl_dir.parent / f"{split}.cache").unlink(missing_ok=True)
        logger.info("wrote %d new %s views to %s (%d in all)", n, split, root, len(keep))
    return write_data_yaml(root)


def _use_threads(threads: int | None) -> None:
    """Make ultralytics' CPU trainer use ``threads`` torch threads (it resets them to ``cpu_count − 1``)."""
    import os

    from ultralytics.utils import torch_utils

    n = int(threads) if threads else (os.cpu_count() or 1)
    torch_utils.NUM_THREADS = max(1, n)


def _pretrained_arg(init: str | Path | None) -> str | bool:
    """Ultralytics' ``pretrained``: ``False`` discards the model's weights, so a new stage passes its init file."""
    return str(Path(init).resolve()) if init is not None else False


def _subset_yaml(data: Path, n_train: int, views: Sequence[int]) -> Path:
    """A data YAML whose train split lists only views ``views`` (0: the full view, 1…: the crops) of each sample
    (no re-rendering)."""
    root = data.parent
    files = [str(root / "images" / "train" / f"{i:06d}_{j}.png") for i in range(n_train) for j in views]
    tag = "".join(str(j) for j in views)
    lst = root / f"train_views{tag}_{n_train}.txt"
    lst.write_text("\n".join(files) + "\n")
    out = root / f"data_views{tag}_{n_train}.yaml"
    out.write_text(data.read_text().replace("train: images/train", f"train: {lst.name}"))
    return out


def _options_tag(options: dict, prefix: str = "_g") -> str:
    """Short stable tag of generator (or other rendering) options for a dataset directory name."""
    import hashlib

    text = json.dumps({k: list(v) if isinstance(v, tuple) else v for k, v in sorted(options.items())})
    return prefix + hashlib.sha256(text.encode()).hexdigest()[:8]


@dataclass
class TrainResult:
    """Outcome of one :func:`train` call: the stage directory and its best / last weights."""

    stage_dir: Path
    best: Path
    last: Path
    resumed: bool


def _stages(out_dir: Path) -> list[Path]:
    return sorted(p for p in out_dir.glob("stage[0-9][0-9]") if p.is_dir())


def _finished(last: Path) -> bool:
    ck = torch.load(last, map_location="cpu", weights_only=False)
    return ck.get("epoch", -1) == -1 or ck.get("optimizer") is None


#: Optimizers ultralytics' trainer knows (``BaseTrainer.build_optimizer``), checked before any data is rendered.
OPTIMIZERS = ("auto", "SGD", "Adam", "Adamax", "AdamW", "NAdam", "RAdam", "RMSprop")


def train(
    out_dir: str | Path, *, samples: Sequence[Sample] | None = None, n_train: int = 1000, n_val: int = 100,
    imgsz: int = 320, epochs: int = 10, batch: int = 16, seed: int = 0, resume: bool = False,
    trust_checkpoints: bool = False,
    init_weights: str | Path | None = None, detector: str = "twostage", crops_per_sample: int = 2,
    workers: int = 2, lr0: float | None = None, crops_used: int | None = None, min_box: float | None = None,
    threads: int | None = None, n_airports: int = DEFAULT_POOL, generate_options: dict | None = None,
    appearance: AppearanceJitter | dict | None = None, crop_jitter: CropJitter | dict | None = None,
    width_loss: float = 0.0, width_loss_min_px: float = 8.0, full_views: bool = True,
    val_samples: Sequence[Sample] | None = None, architecture: str = "yolov8n-pose", **overrides,
) -> TrainResult:
    """Train (or continue training) the runway-corner YOLOv8n-pose.

    Args:
        out_dir: working directory (dataset + stages); created if missing.
        samples: training data (e.g. ``vbl_robust.data.read_lard(...)``); None → ``n_train + n_val`` synthetic
            approaches from ``vbl_robust.scenes.generate(seed=seed)``. Split train/val with ``seed``, unless
            ``val_samples`` are given: then ``samples`` are all training data and ``val_samples`` the validation.
        n_train, n_val: synthetic set sizes (with ``samples``: ``n_val`` is taken from them for validation).
        imgsz: network input side (views are rendered at this size).
        epochs: epochs of this stage.
        batch, workers: ultralytics batch size and data-loader workers.
        seed: seed for data generation, split, crop jitter and ultralytics.
        resume: continue the latest stage (interrupted) or start a new stage from its ``best.pt`` (finished).
        trust_checkpoints: resuming loads the stage's checkpoints, pickles that run code: refused (``ValueError``)
            unless the caller says it trusts them (``--trust-model``).
        init_weights: initial weights of a new first stage (e.g. the shipped model); None → from
            ``architecture``'s ultralytics model file (random init, no hub weights).
        architecture: the network of a first stage trained from scratch, one of :data:`ARCHITECTURES`:
            ``yolov8n-pose`` (every shipped model so far) or ``yolo26n-pose`` (ultralytics' YOLO26: residual
            log-likelihood keypoint loss, issue 49); its head takes the dataset's 4 corners and 1 class. Ignored
            when a stage starts from weights.
        detector: ``"twostage"`` (full views + crops) or ``"single"`` (full views only).
        crops_per_sample: crops per training sample for ``"twostage"`` (rendered).
        crops_used: train on only the first ``crops_used`` of them (more weight on full views, which teach the
            detection itself); None → all.
        lr0: initial learning rate (None: ultralytics' choice).
        min_box: minimum side of the labelled boxes in view pixels; None → ``MIN_BOX_FRACTION · imgsz`` (24 px
            at 320): far runways are 3–7 px wide in a 320 px full view, too small for the anchor assigner to give
            them positives (:func:`~vbl_robust.data.yolo.pose_label`).
        threads: torch intra-op threads for CPU training; None → all cores (ultralytics' own choice is
            ``cpu_count − 1``, i.e. one thread on a 2-core machine).
        n_airports: synthetic airport pool of the generated data (``scenes.generate(n_airports=...)``; each
            airport has its own runway length and width). Few airports let the network learn their runways'
            shape instead of reading it: with 10, held-out runways came out 4–13 % too narrow (MODEL_CARD).
            The validation airports are a different pool (another seed). Ignored with ``samples``.
        generate_options: further keyword arguments of ``scenes.generate`` for the synthetic data, e.g.
            ``{"weights": (2, 1, 1), "runway_length_range_m": (1500, 4500)}`` (far approaches twice as often,
            longer runways); they name the dataset directory, so a different mix never reuses a rendered one.
        appearance: random blur / haze / photometric / noise changes of the training images
            (:class:`~vbl_robust.detect.augment.AppearanceJitter`, or the keyword arguments of one); they name the
            dataset directory too.
        crop_jitter: how the training crops are drawn (:class:`CropJitter`, or the keyword arguments of one;
            None → the default, which matches ``TwoStageDetector()``). A non-default window (e.g. ``min_side=40``:
            far runways magnified 1.6× more) names the dataset directory, and the detector that uses the weights
            must crop alike (``TwoStageDetector(min_side=...)``; ``ship(crop_jitter=...)`` records it).
        width_loss: gain of the threshold-width loss term (:mod:`~vbl_robust.detect.losses`: L1 on the log ratio
            of predicted to true threshold-edge widths, added to ultralytics' keypoint loss); 0 → ultralytics' loss
            alone. Pass the same value again when resuming an interrupted stage.
        width_loss_min_px: edges narrower than this in the training view (pixels) are left out of that term.
        full_views: train on the full views too (default); False → on the crops only, for a pass-2 network of
            its own (``TwoStageDetector(first, second)``). The full views are rendered all the same (the
            dataset is the one a two-stage training uses) and validation keeps them.
        **overrides: further ultralytics training arguments.

    Returns:
        :class:`TrainResult`.
    """
    _check_arguments(detector, architecture, full_views, crops_per_sample, crops_used, imgsz, samples, val_samples,
                     overrides.get("optimizer", "auto"))
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    import_ultralytics()
    from ultralytics import YOLO

    stages = _stages(out_dir)
    if stages and not resume:
        raise ValueError(f"train: {out_dir} already holds training stages; pass resume=True (--resume) to continue")
    if stages and not trust_checkpoints:  # resuming unpickles the stage's last.pt / best.pt: only with consent
        raise ValueError(f"train --resume: the checkpoints in {stages[-1] / 'weights'} are pickles that run code when "
                         "loaded; pass --trust-model if you trust them (e.g. you wrote them)")
    if stages and (stages[-1] / "weights" / "last.pt").exists() and not _finished(stages[-1] / "weights" / "last.pt"):
        last = stages[-1] / "weights" / "last.pt"
        logger.info("resuming %s", last)
        _use_threads(threads)
        with threshold_width_loss(width_loss, width_loss_min_px):
            YOLO(str(last)).train(resume=True)
        return TrainResult(stages[-1], last.with_name("best.pt"), last, True)
    prev = stages[-1] / "weights" / "best.pt" if stages else None
    init = prev if prev is not None and prev.exists() else init_weights
    stage = out_dir / f"stage{len(stages):02d}"

    data = _prepare_data(out_dir, samples, val_samples, n_train=n_train, n_val=n_val, imgsz=imgsz, seed=seed,
                         crops=crops_per_sample if detector == "twostage" else 0, crops_used=crops_used,
                         min_box=min_box, n_airports=n_airports, generate_options=generate_options,
                         appearance=appearance, crop_jitter=crop_jitter, full_views=full_views)

    _use_threads(threads)
    model = YOLO(str(init)) if init is not None else YOLO(f"{architecture}.yaml")
    args = dict(TRAIN_DEFAULTS)
    args.update(data=str(data), imgsz=imgsz, epochs=epochs, batch=batch, workers=workers, seed=seed,
                project=str(out_dir), name=stage.name, exist_ok=True, pretrained=_pretrained_arg(init))
    if lr0 is not None:
        args["lr0"] = lr0
    args.update(overrides)
    logger.info("training %s from %s%s", stage, init or f"{architecture}.yaml",
                f" with threshold-width loss {width_loss:g}" if width_loss else "")
    with threshold_width_loss(width_loss, width_loss_min_px):
        model.train(**args)
    w = stage / "weights"
    return TrainResult(stage, w / "best.pt", w / "last.pt", False)


def _prepare_data(out_dir: Path, samples: Sequence[Sample] | None, val_samples: Sequence[Sample] | None, *,
                  n_train: int, n_val: int, imgsz: int, seed: int, crops: int, crops_used: int | None,
                  min_box: float | None, n_airports: int, generate_options: dict | None,
                  appearance: AppearanceJitter | dict | None, crop_jitter: CropJitter | dict | None,
                  full_views: bool) -> Path:
    """The ``data.yaml`` :func:`train` trains on: the dataset rendered once into a directory of ``out_dir`` named
    by what decides its pixels (reused by later stages), restricted to the views used."""
    if isinstance(crop_jitter, dict):
        crop_jitter = CropJitter(**crop_jitter)
    if crop_jitter == CropJitter():
        crop_jitter = None  # the default window: same directory as before the option existed
    if isinstance(appearance, dict):
        appearance = AppearanceJitter(**{k: tuple(v) if isinstance(v, list) else v for k, v in appearance.items()})
    if min_box is None:
        min_box = round(MIN_BOX_FRACTION * imgsz)
    data_root = out_dir / (f"dataset_{imgsz}px_{crops}crops" + (f"_box{min_box:g}" if min_box else "")
                           + (f"_ap{n_airports}" if samples is None and n_airports != DEFAULT_POOL else "")
                           + (_options_tag(generate_options) if samples is None and generate_options else "")
                           + (_options_tag(appearance.to_dict(), "_app") if appearance is not None else "")
                           + (_options_tag(crop_jitter.__dict__, "_crop") if crop_jitter is not None else ""))
    tr, va = _split(samples, val_samples, n_train, n_val, seed, n_airports, generate_options)
    data = build_dataset(tr, va, data_root, imgsz=imgsz, crops_per_sample=crops, seed=seed, min_box=min_box,
                         appearance=appearance, jitter=crop_jitter)
    used = crops if crops_used is None else min(crops_used, crops)
    if used < crops or not full_views:
        data = _subset_yaml(data, len(tr), ([0] if full_views else []) + list(range(1, used + 1)))
    return data


def _check_arguments(detector: str, architecture: str, full_views: bool, crops_per_sample: int,
                     crops_used: int | None, imgsz: int, samples: Sequence[Sample] | None,
                     val_samples: Sequence[Sample] | None, optimizer: str) -> None:
    """``ValueError`` naming the argument for a :func:`train` call that cannot work (before anything is written)."""
    if detector not in ("single", "twostage"):
        raise ValueError(f"train: detector must be 'single' or 'twostage', got {detector!r}")
    if architecture not in ARCHITECTURES:
        raise ValueError(f"train: architecture must be one of {', '.join(ARCHITECTURES)}, got {architecture!r}")
    if not full_views and (detector != "twostage" or crops_per_sample < 1 or crops_used == 0):
        raise ValueError("train: full_views=False (crops only) needs detector='twostage' and at least one crop")
    if imgsz % 32:
        raise ValueError(f"train: imgsz must be a multiple of 32, got {imgsz}")
    if val_samples is not None and samples is None:
        raise ValueError("train: val_samples needs samples (the training data they validate)")
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"train: optimizer must be one of {', '.join(OPTIMIZERS)}, got {optimizer!r}")


def _split(samples: Sequence[Sample] | None, val_samples: Sequence[Sample] | None, n_train: int, n_val: int,
           seed: int, n_airports: int, generate_options: dict | None) -> tuple[list[Sample], list[Sample]]:
    """The training and validation samples of :func:`train`: generated (``samples`` None), given both, or
    ``samples`` split (a seeded fifth, at most ``n_val``, for validation)."""
    if samples is None:
        from ..scenes.generate import generate

        gen = dict(generate_options or {})
        return (generate(n_train, seed=seed, n_airports=n_airports, **gen),
                generate(n_val, seed=seed + VAL_SEED_OFFSET, n_airports=n_airports, **gen))
    if val_samples is not None:
        tr, va = list(samples), list(val_samples)
        if not tr or not va:
            raise ValueError(f"train: need training and validation samples, got {len(tr)} and {len(va)}")
        return tr, va
    samples = list(samples)
    if len(samples) < 2:
        raise ValueError(f"train: need at least 2 samples, got {len(samples)}")
    order = np.random.default_rng(seed).permutation(len(samples))
    nv = max(1, min(n_val, len(samples) // 5))
    return [samples[i] for i in order[nv:]], [samples[i] for i in order[:nv]]


def ship(weights: str | Path, *, detector: str, imgsz: int, models_dir: str | Path | None = None,
         info: dict | None = None, crop_jitter: CropJitter | None = None) -> Path:
    """Copy trained weights into the package as the default model (optimizer stripped, fp16: a few MB).

    Writes ``runway_yolov8n_pose.pt`` and ``default.json`` (``detector``, ``imgsz`` and ``info``) to
    ``models_dir`` (default: ``vbl_robust/models``). ``crop_jitter``: the training crops' window when it is not
    the default; ``default.json`` then records it (``"twostage": {"margin": …, "min_side": …}``) and the shipped
    two-stage detector crops alike. Returns the weights path.
    """
    if detector not in ("single", "twostage"):
        raise ValueError(f"ship: detector must be 'single' or 'twostage', got {detector!r}")
    info = dict(info or {})
    if crop_jitter is not None and crop_jitter != CropJitter():
        if detector != "twostage":
            raise ValueError("ship: a crop window (crop_jitter) needs detector='twostage'")
        info["twostage"] = {"margin": crop_jitter.margin, "min_side": crop_jitter.min_side}
    import_ultralytics()
    from ultralytics.utils.torch_utils import strip_optimizer

    from .shipped import DEFAULT_MODEL

    version = info.get("version")
    if version is not None and (isinstance(version, bool) or not isinstance(version, int) or version < 1):
        raise ValueError(f"ship: version must be an integer >= 1, got {version!r}")
    src = Path(weights)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: checkpoint not found")
    d = Path(models_dir) if models_dir is not None else DEFAULT_MODEL.parent
    d.mkdir(parents=True, exist_ok=True)
    out = d / DEFAULT_MODEL.name
    # validated before anything is replaced: the stripped copy must be a pose model with the runway's 4 corners
    tmp = d / f".shipping.{DEFAULT_MODEL.name}"  # a .pt name: ultralytics reads a checkpoint by its suffix
    tmp.unlink(missing_ok=True)
    try:
        strip_optimizer(str(src), s=str(tmp))  # logs and writes nothing for a file that is not a checkpoint
        if not tmp.is_file():
            raise ValueError("not an ultralytics checkpoint")
        from ultralytics import YOLO

        model = YOLO(str(tmp))
        kpt = list(getattr(model.model, "kpt_shape", None) or model.model.yaml.get("kpt_shape") or [])
        if model.task != "pose" or kpt[:1] != [4]:
            raise ValueError(f"a {model.task} model with keypoints {kpt}, not a 4-corner pose model")
    except Exception as exc:
        tmp.unlink(missing_ok=True)
        raise ValueError(f"ship: {src}: {exc}; nothing shipped") from None
    os.replace(tmp, out)
    atomic_write(d / "default.json", json.dumps(dict(detector=detector, imgsz=int(imgsz), **info),
                                               indent=1) + "\n")
    return out
