"""The engine's own jobs as specs: ``audit`` (one box searched by the given methods, :func:`audit_spec`) and
``risk`` (a failure probability under a θ distribution, :func:`risk_spec`), and the dense-grid block of an audit's
landscape (:func:`grid_block`), which the paper's experiments (:mod:`vbl_robust.paper.experiments`) build on too.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..constants import TARGETS
from ..specs.budget import Budget
from ..specs.campaign import Block, BoxSpec, CampaignSpec
from ..specs.settings import PipelineSettings

#: ``audit``'s and the demo's methods: georobust-av in place of GeoRobust (it found as many or more breaches at
#: every spatial-2d box on 30 images, in fewer evaluations; BENCHMARKS.md, spatial-2d section).
AUDIT_METHODS = ("georobust-av", "random", "apgd")
#: Batch of a centre-out reference grid that stops at the first breach (the stop is checked once per batch).
GRID_STOP_BATCH = 32


def grid_block(box: BoxSpec, counts: Sequence[int], role: str = "reference", max_samples: int | None = None,
               stop_at_breach: bool = False) -> Block:
    """A dense-grid block over ``box`` (``counts`` nodes per parameter): a reference, or a landscape on
    ``max_samples`` images; ``stop_at_breach``: evaluated from the centre outwards in batches of
    :data:`GRID_STOP_BATCH` and stopped at the first breach."""
    n = 1
    for c in counts:
        n *= int(c)
    grid: dict[str, object] = {"counts": [int(c) for c in counts]}
    if stop_at_breach:  # centre-out, so the grid answers every nested budget before it stops (GridSearch)
        grid.update(order="center-out", batch_size=GRID_STOP_BATCH)
    return Block(boxes=(box,), methods=("grid",), budgets=(Budget(max_evals=n, stop_at_breach=stop_at_breach),),
                 role=role, max_samples=max_samples, options={"grid": grid})


def audit_spec(box: BoxSpec, *, methods: Sequence[str] = AUDIT_METHODS, budget: Budget, seed: int = 0,
               lipschitz: float | tuple[float, ...] | None = None, pnp: str = "ippe_lm",
               landscape: tuple[int, ...] | None = None, sustain: int | None = None,
               target: str = "any") -> CampaignSpec:
    """The ``audit`` job: one box, the given methods and budget; optionally a landscape grid on the first image
    (counts per parameter) for the heat map. ``sustain``: an audit of approach sequences (a sequence campaign,
    :class:`CampaignSpec`), the error sustained over that many consecutive frames. ``target``: a key of
    :data:`vbl_robust.constants.TARGETS` (``"misleading"``: flagged failures count 0 m, so every method searches
    for the worst confident pose)."""
    if target not in TARGETS:
        raise ValueError(f"--target must be one of {', '.join(TARGETS)}, got {target!r}")
    blocks = [Block(boxes=(box,), methods=tuple(methods), budgets=(budget,))]
    if landscape and min(landscape) > 0:
        blocks.append(grid_block(box, landscape, role="landscape", max_samples=1))
    stop = "early stop at the first breach" if budget.stop_at_breach else "no early stop"
    unit = "image" if sustain is None else "sequence"
    figures = ("convergence", "landscape", "progress", "per_image")
    if sustain is not None:
        figures = ("sequences", *figures)
    return CampaignSpec("audit", tuple(blocks), seed=seed, figures=figures,
                        settings=PipelineSettings(penalty_m=TARGETS[target], pnp=pnp, lipschitz=lipschitz,
                                                  sustain=sustain), notes=(
        f"Box {box.label}; methods {', '.join(methods)}; budget per {unit}: {budget.label} ({stop})."
        + ("" if sustain is None else f" One θ held over each approach sequence; its error is the error sustained "
           f"over {sustain} consecutive frame(s).")
        + ("" if lipschitz is None else f" Lipschitz bound given: {lipschitz} m per unit (certificates possible).")
        + ("" if target == "any" else " Target: misleading poses only — a flagged failure (no detection, low "
           "confidence, PnP failed …) counts 0 m, as safe; survival is then the share with no misleading pose "
           "found.")))


def risk_spec(box: BoxSpec, *, methods: Sequence[str] = ("mc", "guided"), max_evals: int = 1024, seed: int = 0,
              dist: dict[str, tuple[str, float, float]] | None = None, tau: float = 0.01, delta: float = 0.05,
              guide_evals: int = 64, pnp: str = "ippe_lm") -> CampaignSpec:
    """The ``risk`` job (:mod:`vbl_robust.risk`): per image, the failure probability under ``dist``
    (parameter → ``("normal", mean, sd)``; uniform elsewhere) over ``box`` by each estimator of ``methods``, at
    most ``max_evals`` evaluations each, and the verdict on "p_fail ≤ ``tau``" at confidence 1 − ``delta``."""
    from ..risk import MAX_EVALS, ThetaDistribution

    if not 0.0 <= tau < 1.0:
        raise ValueError(f"--tau must be in [0, 1), got {tau}")
    if not 0.0 < delta < 1.0:
        raise ValueError(f"--delta must be in (0, 1), got {delta}")
    if not 2 <= max_evals <= MAX_EVALS:
        raise ValueError(f"--max-evals must be in [2, {MAX_EVALS}], got {max_evals}")
    if "guided" in methods and not 1 <= guide_evals < max_evals:  # an option of guided alone
        raise ValueError(f"--guide-evals must be in [1, --max-evals), got {guide_evals}")
    d = ThetaDistribution.over(box.box, dist)  # refuses a parameter not in the box, a normal with no mass
    base = {"dist": {k: list(v) for k, v in sorted((dist or {}).items())}, "tau": tau, "delta": delta}
    options = {m: {**base, **({"guide_evals": guide_evals} if m == "guided" else {})} for m in methods}
    blk = Block(boxes=(box,), methods=tuple(methods), budgets=(Budget(max_evals=max_evals, stop_at_breach=False),),
                kind="risk", options=options)
    return CampaignSpec("risk", (blk,), seed=seed, settings=PipelineSettings(pnp=pnp), figures=("risk",), notes=(
        f"Failure probability p_fail = P(L > ε_safe) per image, θ ~ {d.text()} over {box.label}; estimators "
        f"{', '.join(methods)}, at most {max_evals} evaluations each; verdict on p_fail ≤ {tau:g} at confidence "
        f"{1 - delta:g}."))
