"""The numbers and vocabularies every part of vbl-robust shares, defined once.

- ``EPS_SAFE_M``: the safety threshold ε_safe (metres): a box is safe iff ``max_Θ L ≤ EPS_SAFE_M``.
- ``CONF_THRESHOLD``: the operational confidence threshold τ_conf of the selection σ_select.
- ``PENALTY_M``: the error ``L`` assigned to any failed evaluation (metres; the paper's detection-breakdown value).
- ``FAILURE_REASONS``: why one evaluation failed (it is then penalised with ``PENALTY_M``).
- :class:`Verdict`: the answer for one image and box, used by search, campaigns and report alike.
- :class:`BreachKind`: what kind of failure a breach is — flagged (the system knows it has no fix) or hazardously
  misleading (a confident pose far off).

This module imports nothing of the package, so every part (``search/`` included) may import it.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["CONF_THRESHOLD", "EPS_SAFE_M", "FAILURE_REASONS", "PENALTY_M", "TARGETS", "BreachKind", "Verdict"]

#: ε_safe: the largest acceptable camera-position error, metres (the paper's threshold).
EPS_SAFE_M = 1000.0

#: τ_conf: a candidate is selected only if its confidence is at least this (the paper's operating point).
CONF_THRESHOLD = 0.25

#: L of a failed evaluation (no detection, PnP failure, …), metres (the paper's L_E2E of a breakdown).
PENALTY_M = 5000.0

#: What a search looks for (``--target``): ``"any"`` breach (a flagged failure counts :data:`PENALTY_M`, the
#: paper's convention), or ``"misleading"`` poses only (a flagged failure counts 0 m, as safe, so the search hunts
#: the worst *silent* error: a confident pose far off).
TARGETS: dict[str, float] = {"any": PENALTY_M, "misleading": 0.0}

#: Stated bounds on what a user may ask for (checked before any work; beyond them memory or time runs out, not
#: the tool's answer): images per run, pixels per image side, evaluations per job, points of a dense grid, and the
#: size a stored blob may decompress to.
MAX_IMAGES = 100_000
MAX_IMAGE_SIDE = 8192
MAX_EVALS = 10_000_000
MAX_GRID_POINTS = 2_000_000
MAX_BLOB_BYTES = 512 * 1024 * 1024
#: Largest seed (the store keeps seeds as SQLite's 64-bit integers).
MAX_SEED = 2**63 - 1

#: Why an evaluation failed, with what each code means. ``""`` is a success.
FAILURE_REASONS: dict[str, str] = {
    "image_unavailable": "the sample's pixels could not be loaded",
    "no_detection": "the detector returned no candidate",
    "low_confidence": "the best candidate's confidence is below τ_conf",
    "non_finite_keypoints": "the selected keypoints are not finite",
    "pnp_failed": "the PnP solver found no pose",
    "non_finite_position": "the PnP position is not finite",
    "out_of_view": "the perturbation turned the runway out of the camera's view (a corner behind the camera)",
    "monitor_rejected": "a runtime monitor rejected the pose (its PnP reprojection residual, or its corners' σ propagated "
                        "to the position, above the monitor's limit)",
}


class Verdict(StrEnum):
    """The answer for one image and one box Θ.

    - ``CERTIFIED``: a *sound* upper bound of ``max_Θ L`` is ≤ ε_safe (needs a Lipschitz constant).
    - ``BREACH``: an evaluated θ has ``L > ε_safe`` (a concrete counter-example).
    - ``NO_BREACH_FOUND``: neither; the search did not find a breach within its budget.
    - ``FAILED``: the job itself could not run (the sample cannot be processed at all).
    """

    CERTIFIED = "certified"
    BREACH = "breach"
    NO_BREACH_FOUND = "no breach found"
    FAILED = "failed"



class BreachKind(StrEnum):
    """What an image's result over a box is, as a safety case counts it (integrity apart from availability).

    - ``SAFE``: no evaluation above ε_safe was found.
    - ``FLAGGED``: every evaluation above ε_safe was a *flagged failure* (a reason of :data:`FAILURE_REASONS`: no
      detection, confidence below τ_conf, PnP failed, out of view, …) — the system knows it has no fix and can go
      around (availability is lost).
    - ``MISLEADING``: some evaluation gave a *hazardously misleading* pose — a selected candidate with confidence
      ≥ τ_conf and a PnP position whose error is above ε_safe — the system does not know (integrity is lost).
    """

    SAFE = "safe"
    FLAGGED = "flagged"
    MISLEADING = "misleading"


#: Warning torch 2.14 gives about its own use of ``torch.jit.script`` when torch.func first loads its
#: decompositions (the gradient methods): nothing a user can act on, silenced by the CLI and its worker processes.
TORCH_JIT_WARNING = r"`torch\.jit\.script` is deprecated"
