"""Robust training data from the audit's own search: per training image, the worst of k perturbations.

Worst-of-k training (Engstrom et al., ICML 2019, "Exploring the landscape of spatial robustness": per example, k
random transformations, train on the one with the highest loss) with the loss the audit measures: the pipeline's
position error ``L(θ)`` (:class:`~vbl_robust.pipeline.Objective`, the same detector, σ_select, PnP and 5000 m
penalty), so a round trains on what the audit would report. The perturbations are the audit's
(:class:`~vbl_robust.perturb.Perturbation`): the training view is ``T(x; θ)`` and its corner labels are the
corners moved by the same map — exact for every family, since the attitude is a rotation about the optical centre
(the camera position, hence the PnP target, does not move).

Only *trainable* candidates count: the four corners must stay inside the image after the perturbation (a runway
turned out of the frame teaches nothing a detector could do). The previous round's worst θ of an image joins its
candidates (``previous``), so the pressure keeps up as the model learns.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_write
from ..data.sample import Sample
from ..perturb import Perturbation
from ..space import ParameterBox

__all__ = ["Round", "Worst", "harden", "perturbed_sample", "trainable", "worst_of_k"]


def trainable(sample: Sample, perturbation: Perturbation, theta: np.ndarray) -> np.ndarray:
    """``(N,)`` True where θ row keeps all four corners finite and inside the image (pixel centres at integers,
    the image spans ``[-0.5, W - 0.5] × [-0.5, H - 0.5]``)."""
    pts = perturbation.points(sample.corners_2d, np.atleast_2d(theta), K=sample.K)
    u, v = pts[..., 0], pts[..., 1]
    inside = (u >= -0.5) & (u <= sample.width - 0.5) & (v >= -0.5) & (v <= sample.height - 0.5)
    return np.all(np.isfinite(pts).all(axis=-1) & inside, axis=1)


def perturbed_sample(sample: Sample, perturbation: Perturbation, theta: np.ndarray, *, tag: str = "") -> Sample:
    """The sample as ``T(·; θ)`` shows it: the perturbed pixels (uint8) and the corners moved with them; the same
    ``K``, 3-D corners and camera position; ``R`` unknown (None) when the perturbation turns the camera.
    ``ValueError`` when θ is not :func:`trainable`."""
    theta = np.asarray(theta, dtype=np.float64).reshape(1, -1)
    if not trainable(sample, perturbation, theta)[0]:
        raise ValueError(f"perturbed_sample: θ {theta[0].tolist()} moves a corner of {sample.id} out of the image")
    img = perturbation.images_numpy(sample.image, theta, K=sample.K)[0]
    pixels = np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)
    corners = perturbation.points(sample.corners_2d, theta, K=sample.K)[0]
    out = Sample(id=f"{sample.id}#{tag or 'perturbed'}", K=sample.K, corners_3d=sample.corners_3d, corners_2d=corners,
                 position=sample.position, width=sample.width, height=sample.height,
                 R=None if perturbation.is_geometric else sample.R,
                 meta={**sample.meta, "perturbation": dict(zip(perturbation.names, theta[0].tolist(), strict=True))})
    out.image = pixels
    return out


@dataclass(frozen=True)
class Worst:
    """The worst trainable candidate of one image: θ (real units), its error ``L`` (metres) and how many of the
    candidates were trainable."""

    theta: np.ndarray | None
    value: float
    trainable: int


def worst_of_k(sample: Sample, detector, box: ParameterBox, k: int, rng: np.random.Generator, *,
               previous: Sequence[np.ndarray] = (), pnp: str = "ippe_lm") -> Worst:
    """k θ drawn uniformly in ``box`` (plus ``previous`` worst ones), scored by the audit's ``L(θ)`` on ``detector``;
    the worst trainable one (``theta`` None when no candidate is trainable). One detector call per batch of
    candidates; the draw consumes ``rng`` the same way whatever is trainable."""
    from ..pipeline import Objective

    if k < 1:
        raise ValueError(f"worst_of_k: k must be >= 1, got {k}")
    cand = box.from_unit(rng.random((k, box.dim)))
    if len(previous):
        cand = np.vstack([np.asarray(previous, dtype=np.float64).reshape(-1, box.dim), cand])
    objective = Objective(sample, detector, box, pnp=pnp)
    ok = trainable(sample, objective.perturbation, cand)
    if not ok.any():
        return Worst(None, float("nan"), 0)
    values = np.asarray(objective(cand[ok]).values, dtype=np.float64)
    i = int(np.argmax(values))  # ties: the first (the previous worst, then the draw order)
    return Worst(cand[ok][i], float(values[i]), int(ok.sum()))


@dataclass(frozen=True)
class Round:
    """One hardening round: its directory, the weights it produced, and what its training views were: per
    training image the worst θ found (None: no trainable candidate) and its error on the round's starting model;
    the seconds its search for the worst views and its training took (of this call: a resumed round's training
    counts from its resumption)."""

    index: int
    directory: Path
    weights: Path
    worst: tuple[list[float] | None, ...]
    values: tuple[float, ...]
    breaches: int
    search_s: float | None = None
    train_s: float | None = None

    def to_dict(self) -> dict:
        return {"index": self.index, "weights": str(self.weights), "worst": list(self.worst),
                "values": list(self.values), "breaches": self.breaches, "search_s": self.search_s,
                "train_s": self.train_s}


def harden(out_dir: str | Path, box: ParameterBox, *, train_samples: Sequence[Sample],
           val_samples: Sequence[Sample], init_weights: str | Path | None = None, rounds: int = 2, k: int = 8,
           epochs: int = 2, seed: int = 0, imgsz: int = 320, eps_m: float | None = None, clean: bool = True,
           trust_rounds: bool = False, **train_options) -> list[Round]:
    """Rounds of worst-of-k training (module docstring): each round scores ``k`` candidates per training image on
    the current model (two-stage, ``imgsz``), renders the worst trainable one, and fine-tunes on those views (and
    the clean images when ``clean``) for ``epochs`` with the shipped model's recipe
    (:data:`~vbl_robust.detect.train.FINE_TUNE`; ``train_options`` override it), validating on the clean
    ``val_samples``. ``init_weights``:
    the model to harden (None: the shipped one). Resumable: a finished round (``roundNN/round.json``) is read
    back, an interrupted one resumes its training — both load weights written in ``out_dir`` (pickles), so
    resuming needs ``trust_rounds`` (``--trust-model``), and a round's weights must lie inside ``out_dir``. Returns
    the rounds; ``Round.breaches`` counts the training
    images whose worst θ broke the round's starting model (``L > eps_m``, default ε_safe)."""
    import json
    import time

    from ..constants import EPS_SAFE_M
    from .shipped import DEFAULT_MODEL, DetectorSpec
    from .train import FINE_TUNE, train

    if rounds < 1 or epochs < 1:
        raise ValueError(f"harden: rounds and epochs must be >= 1, got {rounds} and {epochs}")
    eps = EPS_SAFE_M if eps_m is None else float(eps_m)
    out = Path(out_dir)
    perturbation = Perturbation(box)  # ValueError for a box outside a family's domain, before any work
    current = Path(init_weights) if init_weights is not None else None
    previous: list[list[np.ndarray]] = [[] for _ in train_samples]
    done: list[Round] = []
    from_record = False  # whether ``current`` was read back from a round.json (not given by the caller)
    for r in range(rounds):
        rdir = out / f"round{r:02d}"
        record = rdir / "round.json"
        record_read = record.exists()
        if record_read:  # finished earlier: read back
            d = json.loads(record.read_text())
            weights = Path(d["weights"]).resolve()
            if not weights.is_relative_to(out.resolve()):
                raise ValueError(f"{record}: its weights {weights} lie outside {out} (a round's weights are its own)")
            rnd = Round(r, rdir, weights, tuple(d["worst"]), tuple(d["values"]), d["breaches"],
                        d.get("search_s"), d.get("train_s"))
        else:
            if from_record and not trust_rounds:  # the next round loads a recorded round's weights
                raise ValueError(f"harden: resuming loads {current}, a pickle that runs code when loaded; pass "
                                 f"--trust-model if you trust the rounds in {out}")
            det = DetectorSpec.from_choice("default" if current is None else current, design="twostage", trust=True,
                                           options=None if current is None else {"imgsz": imgsz}).build()
            t0 = time.perf_counter()
            worst: list[list[float] | None] = []
            values: list[float] = []
            views: list[Sample] = []
            for i, s in enumerate(train_samples):
                w = worst_of_k(s, det, box, k, np.random.default_rng([seed, r, i]), previous=previous[i])
                worst.append(None if w.theta is None else w.theta.tolist())
                values.append(w.value)
                if w.theta is not None:
                    views.append(perturbed_sample(s, perturbation, w.theta, tag=f"r{r}"))
            t1 = time.perf_counter()
            stage = rdir / "stage00"
            res = train(rdir, samples=[*train_samples, *views] if clean else views, val_samples=val_samples,
                        init_weights=current if current is not None else DEFAULT_MODEL, epochs=epochs, seed=seed,
                        imgsz=imgsz, resume=stage.exists(), trust_checkpoints=trust_rounds,
                        **{**FINE_TUNE, **train_options})
            rnd = Round(r, rdir, res.best, tuple(worst), tuple(values),
                        int(sum(v > eps for v in values if np.isfinite(v))), t1 - t0, time.perf_counter() - t1)
            atomic_write(record, json.dumps(rnd.to_dict(), indent=1) + "\n")
        for i, th in enumerate(rnd.worst):
            if th is not None:
                previous[i] = [np.asarray(th, dtype=np.float64)]
        current, from_record = rnd.weights, record_read
        done.append(rnd)
    return done
