"""The pipeline settings a campaign's jobs share: declared once, here.

:class:`PipelineSettings` is a single field of :class:`~vbl_robust.specs.campaign.CampaignSpec`; the worker receives it
unchanged, and :func:`vbl_robust.campaigns.work.build_objective` turns it, a sample, a detector and a box into the
objective a job maximises. Its dict (:meth:`PipelineSettings.to_dict`, from :func:`dataclasses.asdict`) is part of
every job's context digest and of the stored campaign: a setting added later is written only when it is set
(:data:`WRITTEN_WHEN_SET`), so the keys of campaigns that do not use it stay as they were.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..constants import CONF_THRESHOLD, EPS_SAFE_M, PENALTY_M

__all__ = ["WRITTEN_WHEN_SET", "PipelineSettings"]

#: Settings added after the first stores, with the value they take when unset: written (to the stored campaign and
#: the job context) only when set otherwise.
WRITTEN_WHEN_SET: Mapping[str, Any] = {"clock": "wall", "sustain": None, "monitor_px": None, "monitor_sigma_m": None}


@dataclass(frozen=True)
class PipelineSettings:
    """What the pipeline does with an image, and what a result means: every setting that changes a job's result.

    Attributes:
        eps_safe_m: the safety threshold ε_safe: a worst error above it is a breach (paper: 1000 m).
        penalty_m: the error a failure of the pipeline counts (no detection, low confidence, PnP failed; 5000 m).
        conf_threshold: τ_conf, the confidence below which a detection is not used (0.25).
        pnp: the PnP solver (:data:`vbl_robust.pnp.solvers.SOLVERS`).
        lipschitz: optional Lipschitz constant of L in real units (m per unit of each parameter, or one number for
            the Euclidean norm) — with it, searches that keep a cover of the box can *certify* a sample.
        clock: what time budgets are measured on (:data:`vbl_robust.search.base.CLOCKS`): ``"wall"``, or ``"process"``
            (CPU seconds of the evaluating process, which other work on the machine does not move).
        sustain: ``None`` — every sample is one image and a search job maximises its error; an integer ``k`` — a
            *sequence campaign*: every sample is an :class:`~vbl_robust.data.sequence.ApproachSequence`, one θ is held over
            its frames and a search job maximises the error sustained over ``k`` consecutive frames
            (:class:`~vbl_robust.sequences.objective.SequenceObjective`).
        monitor_px: a runtime monitor of the pipeline: poses whose PnP reprojection residual is above this many
            pixels become flagged failures (:class:`~vbl_robust.pipeline.Objective` ``max_reproj_px``).
        monitor_sigma_m: a runtime monitor for a detector that says how sure it is: poses whose corners' σ,
            propagated through PnP, is above this many metres become flagged failures (``Objective``
            ``max_sigma_m``).
    """

    eps_safe_m: float = EPS_SAFE_M
    penalty_m: float = PENALTY_M
    conf_threshold: float = CONF_THRESHOLD
    pnp: str = "ippe_lm"
    lipschitz: float | tuple[float, ...] | None = None
    clock: str = "wall"
    sustain: int | None = None
    monitor_px: float | None = None
    monitor_sigma_m: float | None = None

    def __post_init__(self) -> None:
        from ..search.base import CLOCKS

        if self.clock not in CLOCKS:
            raise ValueError(f"CampaignSpec: clock must be one of {sorted(CLOCKS)}, got {self.clock!r}")
        if self.sustain is not None and (isinstance(self.sustain, bool) or not isinstance(self.sustain, int)
                                         or self.sustain < 1):
            raise ValueError(f"sustain: need an integer >= 1 (frames), got {self.sustain!r}")
        for value, option, unit in ((self.monitor_px, "--monitor-residual", "pixels"),
                                    (self.monitor_sigma_m, "--monitor-sigma", "metres")):
            if value is None:
                continue
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{option} must be a finite number of {unit} > 0, got {value}")
            if self.sustain is not None:
                raise ValueError(f"{option} applies to image campaigns, not to sequences (--sequences)")
        if isinstance(self.lipschitz, list):
            object.__setattr__(self, "lipschitz", tuple(self.lipschitz))

    def to_dict(self) -> dict[str, Any]:
        """The settings as stored and digested: every field, less those of :data:`WRITTEN_WHEN_SET` left unset."""
        return {k: v for k, v in dataclasses.asdict(self).items()
                if k not in WRITTEN_WHEN_SET or v != WRITTEN_WHEN_SET[k]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> PipelineSettings:
        """The settings of a stored campaign's dict (keys not named here are ignored; a missing later setting is
        unset)."""
        return cls(eps_safe_m=float(d["eps_safe_m"]), penalty_m=float(d["penalty_m"]),
                   conf_threshold=float(d["conf_threshold"]), pnp=d["pnp"], lipschitz=d.get("lipschitz"),
                   **{k: d.get(k, unset) for k, unset in WRITTEN_WHEN_SET.items()})
