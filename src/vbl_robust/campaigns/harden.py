"""Hardening: fine-tune a detector on its own worst cases, round by round (``vbl-robust harden``).

Worst-of-k training (Engstrom et al., ICML 2019, "Exploring the landscape of spatial robustness": per example, k
random transformations, train on the one with the highest loss) with the loss the audit measures: the pipeline's
position error ``L(θ)`` (:class:`~vbl_robust.pipeline.Objective`, the same detector, σ_select, PnP and 5000 m
penalty), so a round trains on what the audit would report. The worst of k is the audit's own random search
(:func:`~vbl_robust.search.maximize` with ``"random"``, k evaluations) over the *trainable* θ: the four corners
must stay inside the image after the perturbation (a runway turned out of the frame teaches nothing a detector
could do), so an untrainable θ is a failed evaluation (:data:`NOT_TRAINABLE`, never the worst) and the search
keeps every point's failure reason and counts its evaluations. The previous round's worst θ of an image joins its
candidates (``previous``), so the pressure keeps up as the model learns. The perturbations are the audit's
(:class:`~vbl_robust.perturb.compose.Perturbation`): the training view is ``T(x; θ)`` and its corner labels are the corners
moved by the same map — exact for every family, since the attitude is a rotation about the optical centre (the
camera position, hence the PnP target, does not move).

The candidates of image ``i`` in round ``r`` are those of the search seeded with :func:`candidate_seed`, the same
draws as the first hardening code's ``default_rng([seed, r, i]).random((k, d))``: the shipped hardened model's
runs would draw the same θ today. Each round is a typed record (:class:`Round`, ``roundNN/round.json``) written
and read back by the same class, with the round's detector identity as its provenance.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write
from ..constants import EPS_SAFE_M
from ..data.sample import Sample
from ..detect.shipped import DEFAULT_MODEL, DetectorSpec
from ..perturb.compose import Perturbation
from ..pipeline import Objective
from ..search.api import maximize
from ..search.evaluations import Evaluations
from ..space import ParameterBox

__all__ = ["NOT_TRAINABLE", "Round", "Worst", "candidate_seed", "harden", "perturbed_sample", "trainable",
           "worst_of_k"]

#: Failure reason of a candidate θ that moves a corner out of the image (value NaN: never the worst).
NOT_TRAINABLE = "not_trainable"


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


def candidate_seed(seed: int, round_index: int, image: int) -> int:
    """The search seed of image ``image`` in round ``round_index``: the integer whose 32-bit words are those of
    ``seed``, ``round_index`` and ``image`` in turn (0 is one word), i.e. the entropy numpy's ``SeedSequence`` reads
    from the list ``[seed, round_index, image]`` — zero words at the end change nothing while the words fit its pool
    of four, which they do for seeds below 2**64. So ``default_rng(candidate_seed(s, r, i))`` draws what
    ``default_rng([s, r, i])`` drew in the first hardening code.

    >>> import numpy as np
    >>> a = np.random.default_rng(candidate_seed(20_261_205, 1, 7)).random(3)
    >>> bool(np.array_equal(a, np.random.default_rng([20_261_205, 1, 7]).random(3)))
    True
    """
    out, shift = 0, 0
    for part in (seed, round_index, image):
        if part < 0:
            raise ValueError(f"candidate_seed: seeds and indices are >= 0, got {part}")
        out |= int(part) << shift
        shift += 32 * max(1, -(-int(part).bit_length() // 32))
    return out


class _Trainable:
    """The audit's ``L(θ)`` on the trainable θ only: an untrainable row is a failed evaluation (NaN,
    :data:`NOT_TRAINABLE`). The ``previous`` worst θ join the first batch's objective call (one detector batch with
    the draws, as they always did); their evaluations are kept in :attr:`kept`, not told to the search."""

    def __init__(self, objective: Objective, sample: Sample, previous: np.ndarray):
        self.objective, self.sample, self.previous = objective, sample, previous
        self.kept: Evaluations | None = None

    def __call__(self, theta: np.ndarray) -> Evaluations:
        n = len(self.previous) if self.kept is None else 0
        theta = np.vstack([self.previous[:n], np.asarray(theta, dtype=np.float64).reshape(-1, self.objective.dim)])
        ok = trainable(self.sample, self.objective.perturbation, theta)
        values = np.full(len(theta), np.nan)
        reasons = [NOT_TRAINABLE] * len(theta)
        if ok.any():
            scored = self.objective(theta[ok])
            values[ok] = np.asarray(scored.values, dtype=np.float64)
            for j, why in zip(np.flatnonzero(ok).tolist(), scored.reasons, strict=True):
                reasons[j] = why
        if self.kept is None:
            self.kept = Evaluations(values[:n], tuple(reasons[:n]))
        return Evaluations(values[n:], tuple(reasons[n:]))


@dataclass(frozen=True)
class Worst:
    """The worst trainable candidate of one image: θ (real units; None when no candidate was trainable), its error
    ``L`` (metres; NaN then) and failure reason (``""``: a pose), how many of the candidates were trainable, and the
    search's bookkeeping: candidates evaluated (``evaluations``, the previous worst included) and failed evaluations
    per reason (``failures``; :data:`NOT_TRAINABLE` counts the untrainable ones)."""

    theta: np.ndarray | None
    value: float
    trainable: int
    reason: str | None = None
    evaluations: int = 0
    failures: dict[str, int] = field(default_factory=dict)


def worst_of_k(sample: Sample, detector: Any, box: ParameterBox, k: int, seed: int, *,
               previous: Sequence[np.ndarray] = (), pnp: str = "ippe_lm") -> Worst:
    """The worst of ``k`` θ drawn uniformly in ``box`` (random search seeded with ``seed``, one batch) and the
    ``previous`` worst ones, scored by the audit's ``L(θ)`` on ``detector`` over the trainable θ (module docstring).
    Ties go to the first: the previous worst, then the draw order. The draws do not depend on what is trainable."""
    if k < 1:
        raise ValueError(f"worst_of_k: k must be >= 1, got {k}")
    prev = np.asarray(previous, dtype=np.float64).reshape(-1, box.dim)
    score = _Trainable(Objective(sample, detector, box, pnp=pnp), sample, prev)
    drawn = maximize(score, box, "random", max_evals=k, batch_size=k, seed=seed)
    kept = score.kept
    thetas = np.vstack([prev, drawn.xs])
    values = np.concatenate([np.asarray(kept.values, dtype=np.float64), drawn.fs])
    reasons = (*kept.reasons, *drawn.reasons)
    failures = dict(sorted(Counter(r for r in reasons if r).items()))
    ok = np.array([r != NOT_TRAINABLE for r in reasons])
    if not ok.any():
        return Worst(None, float("nan"), 0, None, len(reasons), failures)
    i = int(np.argmax(np.where(ok, values, -np.inf)))  # the first of the largest
    return Worst(thetas[i], float(values[i]), int(ok.sum()), reasons[i], len(reasons), failures)


@dataclass(frozen=True)
class Round:
    """One hardening round, as ``roundNN/round.json`` records it (:meth:`write`, :meth:`read`): its directory, the
    weights it produced, and what its training views were — per training image the worst θ found (None: no
    trainable candidate), its error on the round's starting model and the failure reason there (``""``: a pose) —
    how many images broke that model (``breaches``: ``L > eps``), the candidates its search evaluated and their
    failures per reason, the seconds its search for the worst views and its training took (of this call: a resumed
    round's training counts from its resumption), and the identity of the detector the search ran
    (:meth:`~vbl_robust.detect.shipped.DetectorSpec.identity`). Rounds recorded before the search's bookkeeping
    read back with ``reasons`` empty and ``evaluations``, ``detector`` None."""

    index: int
    directory: Path
    weights: Path
    worst: tuple[tuple[float, ...] | None, ...]
    values: tuple[float, ...]
    breaches: int
    search_s: float | None = None
    train_s: float | None = None
    reasons: tuple[str | None, ...] = ()
    evaluations: int | None = None
    failures: dict[str, int] = field(default_factory=dict)
    detector: dict[str, Any] | None = None

    #: The record's file name in the round's directory.
    RECORD = "round.json"

    @classmethod
    def of(cls, index: int, directory: Path, weights: Path, worst: Sequence[Worst], *, eps_m: float,
           search_s: float | None, train_s: float | None, detector: dict[str, Any] | None) -> Round:
        """The round whose search found ``worst`` (one per training image)."""
        failures: Counter[str] = Counter()
        for w in worst:
            failures.update(w.failures)
        return cls(index, Path(directory), Path(weights),
                   tuple(None if w.theta is None else tuple(map(float, w.theta)) for w in worst),
                   tuple(w.value for w in worst), sum(bool(np.isfinite(w.value) and w.value > eps_m) for w in worst),
                   search_s, train_s, tuple(w.reason for w in worst), sum(w.evaluations for w in worst),
                   dict(sorted(failures.items())), detector)

    def to_dict(self) -> dict[str, Any]:
        """The record (JSON types; ``directory`` is where it lies, not in it)."""
        return {"index": self.index, "weights": str(self.weights),
                "worst": [None if w is None else list(w) for w in self.worst], "values": list(self.values),
                "breaches": self.breaches, "search_s": self.search_s, "train_s": self.train_s,
                "reasons": list(self.reasons), "evaluations": self.evaluations, "failures": dict(self.failures),
                "detector": self.detector}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], directory: Path) -> Round:
        """Inverse of :meth:`to_dict`, for the round in ``directory``."""
        return cls(int(d["index"]), Path(directory), Path(d["weights"]),
                   tuple(None if w is None else tuple(map(float, w)) for w in d["worst"]),
                   tuple(float(v) for v in d["values"]), int(d["breaches"]), d.get("search_s"), d.get("train_s"),
                   tuple(d.get("reasons") or ()), d.get("evaluations"), dict(d.get("failures") or {}),
                   d.get("detector"))

    def write(self) -> None:
        atomic_write(self.directory / self.RECORD, json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def read(cls, directory: str | Path) -> Round:
        """The round recorded in ``directory`` (``FileNotFoundError`` when it has not finished)."""
        directory = Path(directory)
        return cls.from_dict(json.loads((directory / cls.RECORD).read_text()), directory)


@dataclass(frozen=True)
class _Plan:
    """What every round of one :func:`harden` call shares."""

    out: Path
    box: ParameterBox
    perturbation: Perturbation
    train_samples: Sequence[Sample]
    val_samples: Sequence[Sample]
    k: int
    epochs: int
    seed: int
    imgsz: int
    eps_m: float
    clean: bool
    trust_rounds: bool
    engine: str
    device: str
    train_options: dict[str, Any]

    def detector(self, weights: Path | None) -> DetectorSpec:
        """The two-stage detector a round searches with: the shipped default model (``weights`` None) or the
        weights a round starts from (already trusted: the caller's ``--model``, or a round's of ``out``)."""
        return DetectorSpec.from_choice("default" if weights is None else weights, design="twostage",
                                        engine=self.engine, device=self.device, trust=True,
                                        options=None if weights is None else {"imgsz": self.imgsz})

    def recorded(self, r: int) -> Round | None:
        """Round ``r`` read back when it finished earlier; its weights must lie inside ``out``."""
        rdir = self.out / f"round{r:02d}"
        if not (rdir / Round.RECORD).exists():
            return None
        rnd = Round.read(rdir)
        weights = rnd.weights.resolve()
        if not weights.is_relative_to(self.out.resolve()):
            raise ValueError(f"{rdir / Round.RECORD}: its weights {weights} lie outside {self.out} (a round's "
                             "weights are its own)")
        return replace(rnd, weights=weights)

    def run(self, r: int, weights: Path | None, previous: Sequence[Sequence[np.ndarray]]) -> Round:
        """Round ``r`` from ``weights``: the worst view per training image, then the fine-tune on them (resumed
        when its stage exists)."""
        from ..detect.train import FINE_TUNE, train  # ultralytics: imported when a round trains

        rdir = self.out / f"round{r:02d}"
        spec = self.detector(weights)
        t0 = time.perf_counter()
        views, worst = self.worst_views(r, spec.build(), previous)
        t1 = time.perf_counter()
        res = train(rdir, samples=[*self.train_samples, *views] if self.clean else views,
                    val_samples=self.val_samples, init_weights=weights if weights is not None else DEFAULT_MODEL,
                    epochs=self.epochs, seed=self.seed, imgsz=self.imgsz, resume=(rdir / "stage00").exists(),
                    trust_checkpoints=self.trust_rounds, **{**FINE_TUNE, **self.train_options})
        rnd = Round.of(r, rdir, res.best, worst, eps_m=self.eps_m, search_s=t1 - t0,
                       train_s=time.perf_counter() - t1, detector=spec.identity())
        rnd.write()
        return rnd

    def worst_views(self, r: int, detector: Any, previous: Sequence[Sequence[np.ndarray]],
                    ) -> tuple[list[Sample], list[Worst]]:
        """Per training image its worst of k on ``detector`` and the view it renders (when trainable)."""
        worst = [worst_of_k(s, detector, self.box, self.k, candidate_seed(self.seed, r, i), previous=previous[i])
                 for i, s in enumerate(self.train_samples)]
        views = [perturbed_sample(s, self.perturbation, w.theta, tag=f"r{r}")
                 for s, w in zip(self.train_samples, worst, strict=True) if w.theta is not None]
        return views, worst


def harden(out_dir: str | Path, box: ParameterBox, *, train_samples: Sequence[Sample],
           val_samples: Sequence[Sample], init_weights: str | Path | None = None, rounds: int = 2, k: int = 8,
           epochs: int = 2, seed: int = 0, imgsz: int = 320, eps_m: float | None = None, clean: bool = True,
           trust_rounds: bool = False, engine: str = "torch", device: str = "cpu", **train_options) -> list[Round]:
    """Rounds of worst-of-k training (module docstring): each round scores ``k`` candidates per training image on
    the current model (two-stage, ``imgsz``, on ``engine`` and ``device``: :meth:`DetectorSpec.from_choice
    <vbl_robust.detect.shipped.DetectorSpec.from_choice>`), renders the worst trainable one, and fine-tunes on those
    views (and the clean images when ``clean``) for ``epochs`` with the shipped model's recipe
    (:data:`~vbl_robust.detect.train.FINE_TUNE`; ``train_options`` override it; the training runs on the CPU),
    validating on the clean ``val_samples``. ``init_weights``: the model to harden (None: the shipped one).
    Resumable: a finished round (``roundNN/round.json``) is read back, an interrupted one resumes its training —
    both load weights written in ``out_dir`` (pickles), so resuming needs ``trust_rounds`` (``--trust-model``), and
    a round's weights must lie inside ``out_dir``. Returns the rounds; ``Round.breaches`` counts the training images
    whose worst θ broke the round's starting model (``L > eps_m``, default ε_safe)."""
    if rounds < 1 or epochs < 1:
        raise ValueError(f"harden: rounds and epochs must be >= 1, got {rounds} and {epochs}")
    plan = _Plan(Path(out_dir), box, Perturbation(box),  # ValueError for a box outside a family's domain
                 train_samples, val_samples, k, epochs, seed, imgsz, EPS_SAFE_M if eps_m is None else float(eps_m),
                 clean, trust_rounds, engine, device, train_options)
    current = Path(init_weights) if init_weights is not None else None
    plan.detector(current)  # and for an engine or device that cannot run: both before any work
    previous: list[Sequence[np.ndarray]] = [() for _ in train_samples]
    done: list[Round] = []
    from_record = False  # whether ``current`` was read back from a round.json (not given by the caller)
    for r in range(rounds):
        rnd = plan.recorded(r)
        if rnd is None and from_record and not trust_rounds:  # the next round loads a recorded round's weights
            raise ValueError(f"harden: resuming loads {current}, a pickle that runs code when loaded; pass "
                             f"--trust-model if you trust the rounds in {plan.out}")
        from_record = rnd is not None
        rnd = rnd if rnd is not None else plan.run(r, current, previous)
        previous = [p if th is None else [np.asarray(th, dtype=np.float64)]
                    for p, th in zip(previous, rnd.worst, strict=True)]
        current = rnd.weights
        done.append(rnd)
    return done
