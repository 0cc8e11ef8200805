"""The paper's experiments as data: each is a function returning a :class:`CampaignSpec` (the engine's own jobs,
``audit`` and ``risk``, are :mod:`vbl_robust.campaigns.audit`).

Defaults are the paper's (ε_safe = 1000 m, τ_conf = 0.25, penalty 5000 m, GeoRobust / random / APGD, 100
images, 1000 for the PnP validation), with georobust-av run beside the paper's GeoRobust, labelled apart. Where the paper leaves a choice open we fix it here and state it in
``notes`` (shown in the report):

- spatial experiments: 200 evaluations per image and box, early stop at the first breach;
- runtime experiments: no early stop (the size of the worst error is measured), time budgets 0.1–5 s and, since
  CPU and GPU times differ, evaluation budgets 10–200 as a machine-independent axis; a time budget counts only
  the evaluations completed within it; the anytime methods (GeoRobust, random, …) run once per image and every
  budget is read off their stamped trace, APGD runs once per budget;
- distance profile: roll budgets 5°, 10°, …, 45° chained per image (a breach at ±b implies one at every larger
  budget, so larger budgets are not searched again), 200 evaluations each;
- perturbation families (``families``): every family of :data:`vbl_robust.perturb.registry.PERTURBATIONS` alone, at its five
  nested budget levels (the registry's ``levels``, mild to extreme; box level = the level index 1–5) chained per
  image like the distance profile, GeoRobust and random (APGD left out, see :func:`families`), 200 evaluations
  per level, and a dense-grid reference per family over its largest level;
- a dense-grid reference (1-D: 0.05° steps) so each figure shows how far each method is from the true worst
  case; in the spatial experiments and the distance profile it runs from 0° outwards and stops at its first
  breach (exact survival per budget for a fraction of the cost); 2-D: a landscape grid on the first image for
  the heat map.

Each spec declares the report's figures it needs (``CampaignSpec.figures``, names from
:data:`~vbl_robust.specs.campaign.FIGURES`): a new experiment gets its figures by declaring them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from fractions import Fraction

from ..campaigns.audit import GRID_STOP_BATCH, grid_block
from ..specs.budget import Budget
from ..specs.campaign import Block, BoxSpec, CampaignSpec, range_text, roll_box, roll_contrast_box

#: The paper's experiments compare the paper's GeoRobust and georobust-av (labelled apart) with random and APGD.
PAPER_METHODS = ("georobust", "georobust-av", "random", "apgd")
ROLL_BUDGETS_DEG = (2.0, 5.0, 10.0, 15.0, 20.0, 30.0)
BOXES_2D = ((2.0, (0.9, 1.1)), (5.0, (0.8, 1.25)), (10.0, (0.7, 1.4)), (15.0, (0.6, 1.6)), (20.0, (0.5, 2.0)),
            (30.0, (0.4, 2.5)))
TIME_BUDGETS_S = (0.1, 0.5, 1.0, 2.0, 5.0)
EVAL_BUDGETS = (10, 25, 50, 100, 200)
DISTANCE_BUDGETS_DEG = (5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0)
ROLL_LIMIT_DEG = 45.0
#: Evaluation cap of the convergence experiment (GeoRobust's published budgets are 2000–3000 evaluations).
CONVERGENCE_MAX_EVALS = 3000
#: Fewest points of a family's dense-grid reference over its largest level (``families``): at least 10 grid steps
#: inside the mildest level of every family of the registry (its largest level is at most 20 times its mildest).
FAMILY_GRID_POINTS = 201
#: Methods of the ``families`` experiment taken out of ``Options.methods`` (see :func:`families`).
FAMILY_EXCLUDED = ("apgd",)


@dataclass(frozen=True)
class Options:
    """Knobs of the experiments (CLI options of ``reproduce``); defaults are the documented ones.

    Attributes:
        methods: searches compared.
        max_evals: per-image evaluation budget of the spatial experiments (and the distance profile).
        grid_step_deg: spacing of the 1-D dense-grid reference; 0 disables it.
        landscape: (roll, contrast) grid counts of the 2-D landscape (first image); (0, 0) disables it.
        time_budgets, eval_budgets: the runtime experiments' budgets.
        iterations: GeoRobust iterations of the convergence experiment.
        family_grid: fewest points of each family's dense-grid reference in ``families`` (rounded up so that the
            levels' bounds and the identity are grid nodes, :func:`family_grid_count`); 0 disables it, and so
            does ``grid_step_deg = 0`` (no reference anywhere).
    """

    methods: tuple[str, ...] = PAPER_METHODS
    max_evals: int = 200
    grid_step_deg: float = 0.05
    landscape: tuple[int, int] = (61, 36)
    time_budgets: tuple[float, ...] = TIME_BUDGETS_S
    eval_budgets: tuple[int, ...] = EVAL_BUDGETS
    iterations: int = 30
    family_grid: int = FAMILY_GRID_POINTS


@dataclass(frozen=True)
class Experiment:
    """A named experiment: its paper section, default number of images and its spec builder (which declares the
    report's figures)."""

    name: str
    title: str
    images: int
    build: Callable[[int, Options], CampaignSpec]


def _roll_grid(half_width: float, step: float, stop_at_breach: bool = False) -> Block | None:
    if step <= 0:
        return None
    return grid_block(roll_box(half_width), [int(round(2 * half_width / step)) + 1], stop_at_breach=stop_at_breach)


def _landscape(box: BoxSpec, counts: tuple[int, int]) -> Block | None:
    if min(counts) <= 0:
        return None
    return grid_block(box, counts, role="landscape", max_samples=1)


def _blocks(*blocks: Block | None) -> tuple[Block, ...]:
    return tuple(b for b in blocks if b is not None)


def _runtime_blocks(box: BoxSpec, o: Options) -> list[Block]:
    """Anytime methods (their points do not depend on the budget): one run per image at the largest time budget
    that also reaches the largest evaluation budget, every budget read off its stamped evaluations. Others
    (APGD: its schedule is fitted to the budget): one run per budget."""
    from ..search.api import anytime_methods

    readable = tuple(m for m in o.methods if m in anytime_methods())
    per_budget = tuple(m for m in o.methods if m not in readable)
    blocks = []
    if readable:
        read = Budget(max_seconds=max(o.time_budgets), stop_at_breach=False, read_seconds=tuple(o.time_budgets),
                      read_evals=tuple(o.eval_budgets))
        blocks.append(Block(boxes=(box,), methods=readable, budgets=(read,)))
    if per_budget:
        blocks += [
            Block(boxes=(box,), methods=per_budget,
                  budgets=tuple(Budget(max_seconds=t, stop_at_breach=False) for t in o.time_budgets)),
            Block(boxes=(box,), methods=per_budget,
                  budgets=tuple(Budget(max_evals=n, stop_at_breach=False) for n in o.eval_budgets)),
        ]
    return blocks


def _runtime_note(o: Options) -> str:
    from ..search.api import anytime_methods

    readable = [m for m in o.methods if m in anytime_methods()]
    per_budget = [m for m in o.methods if m not in readable]
    note = (" A time budget t counts only the evaluations completed by t (the objective is called in chunks, each "
            "stamped with its completion time; the clock covers the method's own work; a chunk never starts after "
            "the budget, and the objective is warmed up once before each timed search).")
    if readable:
        note += (f" {', '.join(readable)}: one run per image at {max(o.time_budgets):g} s and at least "
                 f"{max(o.eval_budgets)} evaluations; every time and evaluation budget is read off its stamped trace "
                 "(their points do not depend on the budget; an evaluation budget n = the run's first n "
                 "evaluations).")
    if per_budget:
        note += f" {', '.join(per_budget)}: one run per budget (its schedule depends on the budget)."
    return note


def pnp_validation(seed: int, o: Options) -> CampaignSpec:
    return CampaignSpec("pnp-validation", (Block(kind="pnp"),), seed=seed, figures=("pnp",), notes=(
        "Every PnP solver on the ground-truth corners and on the detector's corners of the unperturbed image; "
        "errors relative to the slant distance to the runway threshold. The differentiable layer's forward pass "
        "is the ippe_lm solver itself, so its positions equal ippe_lm's (its 'exact' and 'bpnp' modes differ "
        "only in gradients; their agreement is reported as a cosine)."))


def spatial_1d(seed: int, o: Options) -> CampaignSpec:
    main = Block(boxes=tuple(roll_box(b) for b in ROLL_BUDGETS_DEG), methods=o.methods,
                 budgets=(Budget(max_evals=o.max_evals),))
    grid = _roll_grid(max(ROLL_BUDGETS_DEG), o.grid_step_deg, stop_at_breach=True)
    return CampaignSpec("spatial-1d", _blocks(main, grid), seed=seed, figures=("survival", "landscape"), notes=(
        f"Roll budgets ±{', '.join(f'{b:g}' for b in ROLL_BUDGETS_DEG)}°; {o.max_evals} evaluations per image and "
        f"budget, early stop at the first breach. Reference: a dense grid over ±{max(ROLL_BUDGETS_DEG):g}° in "
        f"{o.grid_step_deg:g}° steps, restricted to each budget, evaluated from 0° outwards and stopped at its "
        "first breach: exact survival at every budget (a budget below the breach angle is fully evaluated, every "
        "larger one holds the breach); in a breached budget its worst value is a lower bound."))


def runtime_1d(seed: int, o: Options) -> CampaignSpec:
    box = roll_box(15.0)
    return CampaignSpec("runtime-1d", _blocks(*_runtime_blocks(box, o), _roll_grid(15.0, o.grid_step_deg)), seed=seed,
                        figures=("runtime", "landscape"), notes=(
        f"Roll ±15°; time budgets {', '.join(f'{t:g}' for t in o.time_budgets)} s and evaluation budgets "
        f"{', '.join(map(str, o.eval_budgets))} per image, no early stop. Reference: dense grid in "
        f"{o.grid_step_deg:g}° steps." + _runtime_note(o)))


def spatial_2d(seed: int, o: Options) -> CampaignSpec:
    boxes = tuple(roll_contrast_box(b, c) for b, c in BOXES_2D)
    main = Block(boxes=boxes, methods=o.methods, budgets=(Budget(max_evals=o.max_evals),))
    return CampaignSpec("spatial-2d", _blocks(main, _landscape(boxes[-1], o.landscape)), seed=seed,
                        figures=("survival", "landscape"), notes=(
        f"Roll × contrast boxes from (±2°, [0.9, 1.1]) to (±30°, [0.4, 2.5]); {o.max_evals} evaluations per image "
        f"and box, early stop at the first breach. Landscape: a {o.landscape[0]} × {o.landscape[1]} grid over the "
        "largest box on the first image."))


def runtime_2d(seed: int, o: Options) -> CampaignSpec:
    box = roll_contrast_box(10.0, (0.7, 1.4))
    return CampaignSpec("runtime-2d", _blocks(*_runtime_blocks(box, o), _landscape(box, o.landscape)), seed=seed,
                        figures=("runtime", "landscape"), notes=(
        f"Roll ±10°, contrast [0.7, 1.4]; time budgets {', '.join(f'{t:g}' for t in o.time_budgets)} s and "
        f"evaluation budgets {', '.join(map(str, o.eval_budgets))} per image, no early stop. Landscape: a "
        f"{o.landscape[0]} × {o.landscape[1]} grid on the first image." + _runtime_note(o)))


def distance_profile(seed: int, o: Options) -> CampaignSpec:
    main = Block(boxes=tuple(roll_box(b) for b in DISTANCE_BUDGETS_DEG), methods=o.methods,
                 budgets=(Budget(max_evals=o.max_evals),), chain=True)
    step = 2 * o.grid_step_deg if o.grid_step_deg > 0 else 0.0  # 0.1° by default: 901 points over ±45°
    grid = _roll_grid(ROLL_LIMIT_DEG, step, stop_at_breach=True)
    return CampaignSpec("distance-profile", _blocks(main, grid), seed=seed, figures=("distance", "landscape"), notes=(
        f"Images in quartiles of slant distance. Per image and method, the smallest roll budget of "
        f"{', '.join(f'{b:g}' for b in DISTANCE_BUDGETS_DEG)}° at which a breach is found ({o.max_evals} evaluations "
        f"per budget, early stop; budgets above a breach are implied). φ_crit = the smallest budget at which the "
        f"quartile's survival drops below 10 %, else ≥ {ROLL_LIMIT_DEG:g}°. Reference: dense grid over ±45° in "
        f"{step:g}° steps from 0° outwards, stopped at its first breach (the true breach angle to the step)."))


def convergence(seed: int, o: Options) -> CampaignSpec:
    main = Block(boxes=(roll_box(15.0),), methods=("georobust",),
                 budgets=(Budget(max_iters=o.iterations, max_evals=CONVERGENCE_MAX_EVALS, stop_at_breach=False),))
    return CampaignSpec("convergence", (main,), seed=seed, figures=("convergence",), notes=(
        f"GeoRobust (α = 2), {o.iterations} iterations at ±15°, no early stop: |PO_k| (as selected) and RA(k) = "
        f"Σ vol(PO_k) / vol(Θ) when PO_k is selected. A cap of {CONVERGENCE_MAX_EVALS} evaluations per image (the "
        "GeoRobust paper's budget range) bounds images whose error is flat over a region (e.g. the failure "
        "penalty): there every rectangle ties, PO_k triples at each iteration and the search stops early."))


# -- perturbation families one by one ---------------------------------------------------------------------
def family_boxes(name: str) -> tuple[BoxSpec, ...]:
    """The five nested budget levels of the perturbation family ``name`` as 1-D boxes; box level = the level index
    (1 = mild … 5 = extreme), label = the parameter and its range (``"blur_px [0, 0.5] px"``)."""
    from ..perturb.registry import PERTURBATIONS
    from ..space import ParameterBox

    spec = PERTURBATIONS[name]
    return tuple(BoxSpec(ParameterBox({name: (lo, hi)}), f"{name} {range_text(lo, hi, spec.unit)}", float(k))
                 for k, (lo, hi) in enumerate(spec.levels, start=1))


def family_grid_count(levels: Sequence[tuple[float, float]], identity: float, points: int) -> int:
    """Nodes of a family's dense grid over its largest level: at least ``points``, rounded up to a count that puts
    every level's bounds and the identity on grid nodes (a level's worst case is often at its edge) when that
    needs at most 4 times the requested spacing's steps; else ``points``."""
    lo, hi = levels[-1]
    steps = max(int(points) - 1, 1)
    den = 1
    for v in (identity, *(b for lv in levels for b in lv)):
        den = math.lcm(den, Fraction((v - lo) / (hi - lo)).limit_denominator(1000).denominator)
    k = -(-steps // den) * den
    return k + 1 if k <= 4 * steps else int(points)


def _family_grid(name: str, points: int) -> tuple[Block, str]:
    """The reference grid of one family over its largest level, and how it runs (for the notes).

    Evaluated outwards from the identity and stopped at the first breach where the lattice allows it (exact
    survival at every level for the cost of the breach's distance): centre-out when every level is centred on
    the identity (attitude, brightness), in ascending order when every level starts at it (blurs, haze, noise).
    Levels that are neither (contrast, gamma: multiplicatively symmetric about 1) get the complete grid."""
    from ..perturb.registry import PERTURBATIONS

    spec = PERTURBATIONS[name]
    levels = spec.levels
    n = family_grid_count(levels, spec.identity, points)
    grid: dict[str, object] = {"counts": [n]}
    if all(math.isclose(a + b, 2 * spec.identity, abs_tol=1e-12) for a, b in levels):
        grid.update(order="center-out", batch_size=GRID_STOP_BATCH)
        stop, how = True, "centre-out"
    elif all(a == spec.identity for a, _ in levels):
        grid.update(order="c", batch_size=GRID_STOP_BATCH)
        stop, how = True, "ascending"
    else:
        stop, how = False, "complete"
    box = family_boxes(name)[-1]
    block = Block(boxes=(box,), methods=("grid",), budgets=(Budget(max_evals=n, stop_at_breach=stop),),
                  role="reference", options={"grid": grid})
    return block, f"{n} points, {how}"


def family_methods(o: Options) -> tuple[str, ...]:
    """The methods of ``families``: ``o.methods`` without APGD (:data:`FAMILY_EXCLUDED`), or ``o.methods`` as
    given when nothing else is left (``--methods apgd``)."""
    return tuple(m for m in o.methods if m not in FAMILY_EXCLUDED) or tuple(o.methods)


def families(seed: int, o: Options) -> CampaignSpec:
    """Each perturbation family alone: survival against its five nested budget levels.

    One chained block per family (a breach at a level implies one at every larger, nested level of the same
    family, so larger levels are not searched again), searched with ``Options.methods`` less APGD — GeoRobust
    and random by default: the issue's black-box comparison (APGD is compared on roll in the other experiments;
    a gradient through a blur's σ at 0 or a clamped photometric map adds little on a 1-D box), and the families'
    ranking should not depend on which families a gradient happens to suit. A dense-grid reference per family
    (:func:`_family_grid`) gives the true survival per level up to the grid spacing."""
    from ..perturb.registry import PERTURBATIONS

    methods = family_methods(o)
    budget = Budget(max_evals=o.max_evals)
    blocks: list[Block] = [Block(boxes=family_boxes(name), methods=methods, budgets=(budget,), chain=True)
                           for name in PERTURBATIONS]
    grids = []
    if o.family_grid > 0 and o.grid_step_deg > 0:
        for name in PERTURBATIONS:
            block, how = _family_grid(name, o.family_grid)
            blocks.append(block)
            grids.append(f"{name} {how}")
    levels = "; ".join(f"{name} ({spec.unit}): " + ", ".join(f"L{k} {range_text(lo, hi, spec.unit)}"
                                                             for k, (lo, hi) in enumerate(spec.levels, start=1))
                       for name, spec in PERTURBATIONS.items())
    reference = (f" Reference: per family a dense grid over its largest level ({'; '.join(grids)}; spacing chosen so "
                 "that every level's bounds and the identity are nodes), evaluated outwards from the identity and "
                 "stopped at its first breach where the levels are centred on the identity (centre-out) or start "
                 "at it (ascending), complete otherwise: exact survival at every level up to the grid spacing."
                 if grids else " No dense-grid reference.")
    return CampaignSpec("families", tuple(blocks), seed=seed, figures=("families",), notes=(
        f"Each perturbation family alone, at the five nested budget levels of the perturbation registry (mild to "
        f"extreme; the figures' x-axis is the level index 1–5, FS = fraction of full scale, haze = fraction of "
        f"airlight, contrast and gamma dimensionless): {levels}. Methods {', '.join(methods)} (APGD left out: the "
        f"issue's black-box comparison; it is compared on roll elsewhere); {o.max_evals} evaluations per image, "
        "family and level, early stop at the first breach; levels chained per image and method (a breach at a "
        "level implies one at every larger, nested level, which is not searched again). Families are ranked by "
        "the level at which survival drops below 50 % and below 10 % (an image survives a level when no method, "
        "the grid included, found a breach within it)." + reference))


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment("pnp-validation", "Validation of the PnP solvers", 1000, pnp_validation),
        Experiment("spatial-1d", "Spatial robustness to 1-D camera roll", 100, spatial_1d),
        Experiment("runtime-1d", "Runtime robustness, roll ±15°", 100, runtime_1d),
        Experiment("spatial-2d", "Spatial robustness to roll and contrast", 100, spatial_2d),
        Experiment("runtime-2d", "Runtime robustness, roll ±10° and contrast [0.7, 1.4]", 100, runtime_2d),
        Experiment("distance-profile", "Vulnerability profile by approach distance", 100, distance_profile),
        Experiment("convergence", "GeoRobust convergence and search-space reduction", 100, convergence),
        Experiment("families", "Perturbation families one by one: survival vs budget level", 100, families),
    )
}


#: The paper's seven experiments (``reproduce paper``); ``all`` adds ours (``families``).
PAPER = tuple(name for name in EXPERIMENTS if name != "families")
#: Each experiment's report title, by campaign name: what the commands above the report give
#: :func:`vbl_robust.report.build.build_report` (``titles``), which cannot import the paper.
EXPERIMENT_TITLES = {name: e.title for name, e in EXPERIMENTS.items()}


def experiment(name: str) -> Experiment:
    """The experiment called ``name`` (``ValueError`` listing the names otherwise)."""
    try:
        return EXPERIMENTS[name]
    except KeyError:
        raise ValueError(f"unknown experiment {name!r}; experiments are: {', '.join(EXPERIMENTS)}") from None


def with_options(o: Options, **changes: object) -> Options:
    """``o`` with the non-None ``changes`` applied (CLI overrides)."""
    return replace(o, **{k: v for k, v in changes.items() if v is not None})
