"""Campaigns as data: a spec (boxes × methods × budgets, per block) expands into jobs with a seed stream.

A :class:`CampaignSpec` holds the settings shared by all its jobs (ε_safe, τ_conf, failure penalty, PnP
solver, base seed) and a tuple of :class:`Block` s. A block is one cross product *samples × boxes × methods ×
budgets*; experiments use several blocks (the searches, a dense-grid reference, a landscape on one image).

Every :class:`Job` has a stable ``key``: the SHA-256 of its canonical JSON (sorted keys, plain floats) together
with the *context* (detector identity, dataset identity, shared settings). The key is what makes a campaign
resumable: the results store holds one row per key, so a rerun of the same command skips finished jobs.

Seed stream: each job's seed is derived from the base seed and the job's identity (sample, method, box,
budget) by hashing, so it does not depend on the order of jobs or on which jobs were already done.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ..digest import canonical_json, digest
from ..space import ParameterBox
from .budget import Budget
from .kinds import JobKind, Role
from .settings import PipelineSettings

__all__ = ["FIGURES", "JOB_KINDS", "ROLES", "Block", "BoxSpec", "CampaignSpec", "Job", "box_label",
           "default_figures", "derive_seed", "levels_text", "range_text", "roll_box", "roll_contrast_box",
           "unit_suffix"]


#: The values of :class:`JobKind` and :class:`Role`, in order.
JOB_KINDS = tuple(k.value for k in JobKind)
ROLES = tuple(r.value for r in Role)
#: Figures (report sections) a campaign can declare, with the rows each one draws:
#: ``pnp`` — the PnP-solver comparison (``kind="pnp"`` blocks); ``survival`` — survival against the box level
#: (main, unchained blocks with several boxes; plus the reference grid); ``runtime`` — survival and median worst
#: error against the per-image budget (main blocks with several time or evaluation budgets); ``distance`` —
#: φ_crit per slant-distance quartile (chained main blocks); ``families`` — per perturbation family (the parameter
#: of 1-D main boxes, level = budget index) survival against the level and the families ranked by the level at
#: which survival drops below 50 % and 10 % (plus the reference grids); ``convergence`` — |PO_k| and RA(k) of
#: DIRECT-family traces; ``landscape`` — L over a dense grid of one image (landscape role, else the reference grid) with the
#: methods' points; ``progress`` — worst error found against evaluations; ``per_image`` — each image's worst case.
#: ``sequences`` — a sequence campaign's errors along each approach and its per-sequence breach facts; ``risk`` —
#: each image's failure probability under the θ distribution (``kind="risk"`` blocks) and the pooled rate.
FIGURES = ("pnp", "risk", "survival", "runtime", "distance", "families", "sequences", "convergence", "landscape",
           "progress", "per_image")


def derive_seed(base_seed: int, *parts: Any) -> int:
    """A seed in ``[0, 2**31)`` derived from ``base_seed`` and the identity ``parts`` (order independent of jobs)."""
    h = hashlib.sha256(canonical_json([int(base_seed), *parts]).encode()).digest()
    return int.from_bytes(h[:4], "big") & 0x7FFFFFFF


@dataclass(frozen=True)
class BoxSpec:
    """A labelled perturbation box; ``level`` is the number plotted on a budget axis (e.g. the roll half-width)."""

    box: ParameterBox
    label: str
    level: float

    def to_dict(self) -> dict[str, Any]:
        return {"box": self.box.to_dict(), "label": self.label, "level": self.level}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BoxSpec:
        return cls(ParameterBox.from_dict(d["box"]), d["label"], float(d["level"]))


def box_label(bounds: Mapping[str, tuple[float, float]]) -> str:
    """The short label of a box (part of its jobs' seeds): ``"±15°, c∈[0.7, 1.4]"`` — a symmetric roll as ``±b°``,
    another roll range as ``roll∈[lo, hi]°``, contrast as ``c∈[lo, hi]``, any other parameter as ``name∈[lo, hi]``."""
    parts = []
    for k, (lo, hi) in bounds.items():
        if k == "roll_deg":
            parts.append(f"±{hi:g}°" if lo == -hi else f"roll∈[{lo:g}, {hi:g}]°")
        else:
            parts.append(f"{'c' if k == 'contrast' else k}∈[{lo:g}, {hi:g}]")
    return ", ".join(parts)


#: How a unit prints in a level's range (dimensionless units print nothing; FS = fraction of full scale): part of
#: a perturbation family's box labels (:func:`range_text`), so of its jobs' seeds, like :func:`box_label`.
_UNIT_SUFFIX = {"deg": "°", "px": " px", "full scale": " FS"}


def unit_suffix(unit: str) -> str:
    """How ``unit`` follows a number in a range (``"°"``, ``" px"``, ``" FS"``; ``""`` when dimensionless)."""
    return _UNIT_SUFFIX.get(unit, "")


def range_text(lower: float, upper: float, unit: str = "") -> str:
    """A budget level's range in its unit: ``±2°``, ``[0, 0.5] px``, ``[0.9, 1.1]``, ``±0.05 FS``."""
    if lower == -upper and upper > 0:
        return f"±{upper:g}{unit_suffix(unit)}"
    return f"[{lower:g}, {upper:g}]{unit_suffix(unit)}"


def levels_text(bounds: Sequence[tuple[float, float]], unit: str = "") -> str:
    """Nested levels in short form: ``±2/5/10/20/30°``, ``0 to 0.5/1/2/4/8 px``, ``[0.9, 1.1] … [0.4, 2.5]``."""
    if not bounds:
        return ""
    his = "/".join(f"{hi:g}" for _, hi in bounds)
    if all(lo == -hi and hi > 0 for lo, hi in bounds):
        return f"±{his}{unit_suffix(unit)}"
    if len({lo for lo, _ in bounds}) == 1:
        return f"{bounds[0][0]:g} to {his}{unit_suffix(unit)}"
    if len(bounds) == 1:
        return range_text(*bounds[0], unit)
    return f"{range_text(*bounds[0], unit)} … {range_text(*bounds[-1], unit)}"


def roll_box(half_width_deg: float) -> BoxSpec:
    """The 1-D box roll ∈ [−b, b] degrees."""
    b = abs(float(half_width_deg))
    bounds = {"roll_deg": (-b, b)}
    return BoxSpec(ParameterBox(bounds), box_label(bounds), b)


def roll_contrast_box(half_width_deg: float, contrast: tuple[float, float]) -> BoxSpec:
    """The 2-D box roll ∈ [−b, b] degrees × contrast ∈ [lo, hi]."""
    b = abs(float(half_width_deg))
    bounds = {"roll_deg": (-b, b), "contrast": (float(contrast[0]), float(contrast[1]))}
    return BoxSpec(ParameterBox(bounds), box_label(bounds), b)


@dataclass(frozen=True)
class Block:
    """One cross product samples × boxes × methods × budgets.

    Attributes:
        boxes, methods, budgets: the factors.
        role: "main" (compared searches), "reference" (dense grid: the true worst case), "landscape" (dense
            grid on a few images for the heat map).
        kind: "search", "pnp" (the PnP-solver comparison: one job per image; boxes/methods/budgets unused) or
            "risk" (a failure-probability estimate per image, box, method and budget).
        max_samples: only the first ``max_samples`` samples (None: all).
        chain: per (sample, method), run boxes in order and, once a breach is found at a box, record the larger
            boxes as implied breaches without searching (used for the smallest breaching roll budget; boxes
            must be nested, over the same parameters, and sorted by level). Each chained block is a chain of its
            own (two blocks' chains never imply each other's boxes).
        options: per-method keyword options for the search (e.g. ``{"grid": {"counts": [1201]}}``).
    """

    boxes: tuple[BoxSpec, ...] = ()
    methods: tuple[str, ...] = ()
    budgets: tuple[Budget, ...] = ()
    role: Role = Role.MAIN
    kind: JobKind = JobKind.SEARCH
    max_samples: int | None = None
    chain: bool = False
    options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"Block: role must be one of {ROLES}, got {self.role!r}")
        if self.kind not in JOB_KINDS:
            raise ValueError(f"Block: kind must be one of {JOB_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "role", Role(self.role))
        object.__setattr__(self, "kind", JobKind(self.kind))
        if self.kind in (JobKind.SEARCH, JobKind.RISK) and not (self.boxes and self.methods and self.budgets):
            raise ValueError(f"Block: a {self.kind} block needs at least one box, one method and one budget")
        if self.kind == JobKind.RISK and (self.chain or self.role != Role.MAIN):
            raise ValueError("Block: a risk block is a main block without a chain")
        if self.chain:
            levels = [b.level for b in self.boxes]
            if levels != sorted(levels):
                raise ValueError(f"Block: chained boxes must be sorted by level, got {levels}")
            names = {b.box.names for b in self.boxes}
            if len(names) > 1:
                raise ValueError(f"Block: chained boxes must share their parameters, got {sorted(names)}")


@dataclass(frozen=True)
class Job:
    """One unit of work: one search (or PnP comparison) on one sample. Rows of the store are keyed by ``key``."""

    experiment: str
    sample_id: str
    sample_fp: str
    sample_index: int
    kind: JobKind
    role: Role
    method: str
    box: BoxSpec | None
    budget: Budget | None
    seed: int
    options: Mapping[str, Any]
    context: str
    chain: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", JobKind(self.kind))
        object.__setattr__(self, "role", Role(self.role))

    def identity(self) -> dict[str, Any]:
        """Everything that determines the job's result (the key is its digest)."""
        return {
            "experiment": self.experiment,
            "sample_id": self.sample_id,
            "sample_fp": self.sample_fp,
            "kind": self.kind.value,
            "role": self.role.value,
            "method": self.method,
            "box": None if self.box is None else self.box.to_dict(),
            "budget": None if self.budget is None else self.budget.to_dict(),
            "seed": self.seed,
            "options": dict(self.options),
            "context": self.context,
        }

    @property
    def key(self) -> str:
        return digest(self.identity(), 40)

    def to_dict(self) -> dict[str, Any]:
        d = self.identity()
        d.update(sample_index=self.sample_index, chain=self.chain)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Job:
        return cls(
            experiment=d["experiment"], sample_id=d["sample_id"], sample_fp=d["sample_fp"],
            sample_index=int(d["sample_index"]),
            kind=d["kind"], role=d["role"], method=d["method"],
            box=None if d["box"] is None else BoxSpec.from_dict(d["box"]),
            budget=None if d["budget"] is None else Budget.from_dict(d["budget"]),
            seed=int(d["seed"]), options=dict(d["options"]), context=d["context"], chain=d.get("chain"),
        )


def default_figures(blocks: Sequence[Block]) -> tuple[str, ...]:
    """The figures a campaign shows when it declares none (e.g. a store written before figures were declared),
    from what its blocks hold (see :data:`FIGURES`)."""
    out: set[str] = set()
    for b in blocks:
        if b.kind in (JobKind.PNP, JobKind.RISK):
            out.add(b.kind.value)
        elif b.role in (Role.REFERENCE, Role.LANDSCAPE):
            out.add("landscape")
        elif b.chain:
            out.add("distance")
        else:
            if len(b.boxes) > 1:
                out.add("survival")
            if len(b.budgets) > 1:
                out.add("runtime")
            if len(b.boxes) == 1 and len(b.budgets) == 1:
                out.update(("convergence", "progress", "per_image"))
    return tuple(f for f in FIGURES if f in out)


@dataclass(frozen=True)
class CampaignSpec:
    """A campaign: shared settings plus blocks. :meth:`expand` turns it into jobs for a list of sample ids.

    Attributes:
        name: experiment name ("audit", "spatial-1d", …); part of every job key.
        blocks: the cross products.
        seed: base of the seed stream.
        settings: the pipeline settings every job shares (:class:`~vbl_robust.specs.settings.PipelineSettings`:
            ε_safe, the failure penalty, τ_conf, the PnP solver, the Lipschitz constant, the clock, a sequence
            campaign's ``sustain``, the runtime monitors); part of every job's context.
        notes: free text for the report (budgets chosen, deviations from the paper).
        figures: the report's figures (names from :data:`FIGURES`; the report draws them in that order);
            empty: :func:`default_figures` of the blocks. Presentation only: not part of any job key.
    """

    name: str
    blocks: tuple[Block, ...]
    seed: int = 0
    settings: PipelineSettings = field(default_factory=PipelineSettings)
    notes: str = ""
    figures: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.settings, PipelineSettings):
            raise TypeError(f"CampaignSpec: settings must be a PipelineSettings, got {type(self.settings).__name__}")
        unknown = [f for f in self.figures if f not in FIGURES]
        if unknown:
            raise ValueError(f"CampaignSpec: unknown figure(s) {unknown}; figures are {FIGURES}")
        if self.settings.sustain is not None and any(b.kind != JobKind.SEARCH for b in self.blocks):
            raise ValueError("CampaignSpec: a sequence campaign (sustain set) holds search blocks only")
        object.__setattr__(self, "figures", tuple(self.figures))

    def check(self) -> None:
        """Refuse, before any work, a campaign the pipeline cannot run as asked: ``ValueError``, one line naming
        the setting and its value (a box outside a perturbation family's domain, an unknown PnP solver or search
        method, a method given twice in a block, a Lipschitz constant of the wrong length). Without this such a
        campaign would run and record every job as failed — "every image unsafe" from a typing error."""
        from ..perturb.compose import Perturbation
        from ..pnp.solvers import SOLVERS
        from ..search.api import METHODS
        from ..search.bounds import check_lipschitz

        if self.settings.pnp not in SOLVERS:
            raise ValueError(f"pnp: unknown solver {self.settings.pnp!r}; solvers are {', '.join(SOLVERS)}")
        from ..risk import RISK_METHODS

        for blk in self.blocks:
            if blk.kind == JobKind.PNP:
                continue
            known = RISK_METHODS if blk.kind == JobKind.RISK else METHODS
            unknown = [m for m in blk.methods if m not in known]
            if unknown:
                raise ValueError(f"methods: unknown method(s) {unknown}; methods are {', '.join(known)}")
            twice = sorted({m for m in blk.methods if blk.methods.count(m) > 1})
            if twice:
                raise ValueError(f"methods: {', '.join(twice)} given more than once")
            graded = [m for m in blk.methods if blk.kind != JobKind.RISK and METHODS[m].needs_gradient]
            if self.settings.monitor_sigma_m is not None and graded:  # the σ monitor reads the black-box path only
                raise ValueError(f"--monitor-sigma: a gradient search ({', '.join(graded)}) cannot run under the σ "
                                 "monitor; leave it out of --methods")
            for box in blk.boxes:
                try:
                    Perturbation(box.box)
                    check_lipschitz(self.settings.lipschitz, "2", box.box.dim)
                except ValueError as exc:
                    raise ValueError(f"box {box.label}: {exc}") from None
            if "grid" in blk.methods:  # a lattice beyond MAX_GRID_POINTS is refused here, not as failed jobs
                from ..search.api import make_optimizer

                for box in blk.boxes:
                    for budget in blk.budgets:
                        try:
                            make_optimizer("grid", box.box, max_evals=budget.max_evals, **blk.options.get("grid", {}))
                        except ValueError as exc:
                            raise ValueError(f"dense grid on box {box.label}: {exc}") from None

    @property
    def unit(self) -> str:
        """What one sample is, for tables and text: ``"image"``, or ``"sequence"`` in a sequence campaign."""
        return "image" if self.settings.sustain is None else "sequence"

    def check_samples(self, samples: Sequence[Any]) -> None:
        """Refuse, before any work, samples this campaign cannot run on: ``ValueError``, one line — images given to
        a sequence campaign or sequences to an image campaign, or a sequence shorter than ``sustain`` frames
        (every job of it would fail)."""
        for s in samples:
            frames = getattr(s, "samples", None)
            if self.settings.sustain is None and frames is not None:
                raise ValueError(f"sample {s.id!r} is an approach sequence: a campaign of sequences needs sustain")
            if self.settings.sustain is not None and frames is None:
                raise ValueError(f"sample {s.id!r} is one image: a sequence campaign (sustain {self.settings.sustain}) needs "
                                 "approach sequences")
            if self.settings.sustain is not None and len(frames) < self.settings.sustain:
                raise ValueError(f"sustain: need an integer k with 1 <= k <= {len(frames)} (sequence {s.id!r} has "
                                 f"{len(frames)} frames), got {self.settings.sustain}")

    @property
    def report_figures(self) -> tuple[str, ...]:
        """The figures the report draws: the declared ones, else :func:`default_figures` of the blocks (with
        ``sequences`` for a sequence campaign)."""
        if self.figures:
            return self.figures
        found = default_figures(self.blocks) + (("sequences",) if self.settings.sustain is not None else ())
        return tuple(f for f in FIGURES if f in found)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name, "seed": self.seed, **self.settings.to_dict(), "notes": self.notes, "figures": list(self.figures),
            "blocks": [
                {"boxes": [b.to_dict() for b in blk.boxes], "methods": list(blk.methods),
                 "budgets": [b.to_dict() for b in blk.budgets], "role": blk.role.value, "kind": blk.kind.value,
                 "max_samples": blk.max_samples, "chain": blk.chain, "options": {k: dict(v) for k, v in blk.options.items()}}
                for blk in self.blocks
            ],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CampaignSpec:
        blocks = tuple(
            Block(boxes=tuple(BoxSpec.from_dict(b) for b in blk["boxes"]), methods=tuple(blk["methods"]),
                  budgets=tuple(Budget.from_dict(b) for b in blk["budgets"]), role=blk["role"], kind=blk["kind"],
                  max_samples=blk["max_samples"], chain=blk["chain"], options=blk["options"])
            for blk in d["blocks"]
        )
        return cls(name=d["name"], blocks=blocks, seed=int(d["seed"]), settings=PipelineSettings.from_dict(d),
                   notes=d.get("notes", ""), figures=tuple(d.get("figures", ())))

    def with_settings(self, **changes: Any) -> CampaignSpec:
        """This campaign with ``changes`` to its pipeline settings (checked as a new :class:`PipelineSettings`)."""
        return replace(self, settings=replace(self.settings, **changes))

    def context(self, detector_id: str) -> str:
        """Digest of what every job of this campaign shares: the settings and the detector identity."""
        return digest({"settings": self.settings.to_dict(), "detector": detector_id}, 24)

    def search_methods(self) -> set[str]:
        """The methods its search blocks run."""
        return {m for b in self.blocks if b.kind == JobKind.SEARCH for m in b.methods}

    def with_method_options(self, options: Mapping[str, Mapping[str, Any]], *, strict: bool = True) -> CampaignSpec:
        """This campaign with ``options[method]`` merged into the options of every search block that runs
        ``method`` (over the block's own, e.g. a grid's counts stay unless named). Raises a ValueError naming the
        method or option when no block runs a method (unless not ``strict``: such methods are then ignored, as
        when one option set serves several experiments), or a method rejects its options (checked here, on each
        block's first box, so that a campaign never starts with options its searches would refuse). The options
        are part of the job keys: a run with other options never resumes one without them."""
        from ..search.api import make_optimizer

        blocks, used = [], set()
        for blk in self.blocks:
            touched = [m for m in blk.methods if m in options] if blk.kind == JobKind.SEARCH else []
            if not touched:
                blocks.append(blk)
                continue
            merged = {m: dict(v) for m, v in blk.options.items()}
            for m in touched:
                merged[m] = {**merged.get(m, {}), **dict(options[m])}
                if blk.boxes:
                    try:
                        make_optimizer(m, blk.boxes[0].box, **merged[m])
                    except (TypeError, ValueError) as exc:
                        raise ValueError(f"{self.name}: options {merged[m]} of method {m!r}: {exc}") from None
            used.update(touched)
            blocks.append(replace(blk, options=merged))
        missing = sorted(set(options) - used)
        if missing and strict:
            raise ValueError(f"{self.name}: no search runs method(s) {missing} (its methods: "
                             f"{sorted(self.search_methods())})")
        return replace(self, blocks=tuple(blocks))

    def expand(self, samples: Sequence[tuple[str, str]], *, detector_id: str = "") -> list[Job]:
        """All jobs for ``samples`` = ``(id, geometry fingerprint)`` pairs, ordered by sample, then block, then
        method, budget, box (chained jobs in box order).

        The fingerprint (see :func:`vbl_robust.campaigns.provenance.sample_fingerprint`) makes a job key change
        when a sample with the same id has other geometry, while growing a dataset keeps the existing keys.
        """
        ids = [sid for sid, _ in samples]
        if len(set(ids)) != len(ids):
            raise ValueError("CampaignSpec.expand: sample ids must be unique")
        ctx = self.context(detector_id)
        jobs: list[Job] = []
        for i, (sid, fp) in enumerate(samples):
            for blk in self.blocks:
                if blk.max_samples is not None and i >= blk.max_samples:
                    continue
                if blk.kind == JobKind.PNP:
                    jobs.append(Job(self.name, sid, fp, i, JobKind.PNP, blk.role, "pnp", None, None,
                                    derive_seed(self.seed, sid, "pnp"), {}, ctx))
                    continue
                for method in blk.methods:
                    opts = dict(blk.options.get(method, {}))
                    for budget in blk.budgets:
                        # the boxes' labels keep the chains of two blocks apart (e.g. one per perturbation family)
                        chain = (digest([sid, blk.role.value, method, budget.to_dict(), [b.label for b in blk.boxes]], 16)
                                 if blk.chain else None)
                        for box in blk.boxes:
                            seed = derive_seed(self.seed, sid, method, box.label, budget.label)
                            jobs.append(Job(self.name, sid, fp, i, blk.kind, blk.role, method, box, budget, seed,
                                            opts, ctx, chain))
        return jobs
