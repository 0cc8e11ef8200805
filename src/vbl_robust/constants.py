"""The numbers and vocabularies every part of vbl-robust shares, defined once.

- ``EPS_SAFE_M``: the safety threshold ε_safe (metres): a box is safe iff ``max_Θ L ≤ EPS_SAFE_M``.
- ``CONF_THRESHOLD``: the operational confidence threshold τ_conf of the selection σ_select.
- ``PENALTY_M``: the error ``L`` assigned to any failed evaluation (metres; the paper's detection-breakdown value).
- ``FAILURE_REASONS``: why one evaluation of the pipeline under test failed (a *flagged* failure of the pipeline,
  penalised with ``PENALTY_M``).
- :class:`NotMeasured`: why the *tool* could not complete a job (an input missing, a method that cannot run on this
  model, an exception in our code or in the detector) — not a finding about the pipeline; :class:`NotMeasuredError`
  carries it. The line between the two kinds of failure is drawn here, once: a reason of ``FAILURE_REASONS`` is
  the pipeline's and counts against it, a :class:`NotMeasured` reason is the tool's and enters no rate.
- :class:`Verdict`: the answer for one image and box, used by search, campaigns and report alike.
- :class:`BreachKind`: what kind of failure a breach is — flagged (the system knows it has no fix) or hazardously
  misleading (a confident pose far off).

This module imports nothing of the package, so every part (``search/`` included) may import it.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["CONF_THRESHOLD", "EPS_SAFE_M", "FAILURE_REASONS", "PENALTY_M", "TARGETS", "BreachKind", "NotMeasured",
           "NotMeasuredError", "Verdict"]

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

#: Why an evaluation of the pipeline under test failed, with what each code means (``""`` is a success). Each is
#: a *flagged* failure of the pipeline: it counts against it. A failure of the tool (the pixels cannot be loaded, a
#: method that cannot run on the detector) is none of these: it is :class:`NotMeasured`.
FAILURE_REASONS: dict[str, str] = {
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
    - ``NOT_MEASURED``: the tool could not complete the job (:class:`NotMeasured` says why): no answer about the
      pipeline at all — it enters no rate. Stores written before this name read their ``"failed"`` as it.
    """

    CERTIFIED = "certified"
    BREACH = "breach"
    NO_BREACH_FOUND = "no breach found"
    NOT_MEASURED = "not measured"

    @classmethod
    def _missing_(cls, value: object) -> Verdict | None:
        return cls.NOT_MEASURED if value == "failed" else None


class NotMeasured(StrEnum):
    """Why the tool could not complete a job — never a property of the pipeline under test, so never in a rate
    (not as :data:`PENALTY_M`, not as 0 m): listed apart with its reason, and the commands exit 1 unless told
    ``--allow-unmeasured``.

    - ``INPUT_UNAVAILABLE``: an input is missing or unreadable (an image file absent, truncated or of another size
      than the camera model states).
    - ``METHOD_UNFIT``: the method cannot run on this detector (a gradient search on a model without gradients).
    - ``DETECTOR_ERROR``: an exception inside the detector (a user's model or plugin).
    - ``TOOL_ERROR``: an exception in vbl-robust's own code.

    A worker process that dies leaves its jobs pending (the run ends incomplete, exit 1; a rerun resumes them).
    """

    INPUT_UNAVAILABLE = "input unavailable"
    METHOD_UNFIT = "method unfit"
    DETECTOR_ERROR = "detector error"
    TOOL_ERROR = "tool error"

    @classmethod
    def of(cls, reason: str | None) -> NotMeasured:
        """The kind of a stored not-measured job's reason (``"<kind>: <detail>"``); reasons stored before the
        kinds were named: ``"image unavailable: …"`` → ``INPUT_UNAVAILABLE``, any other → ``TOOL_ERROR``."""
        head = (reason or "").partition(":")[0].strip()
        if head == "image unavailable":
            return cls.INPUT_UNAVAILABLE
        try:
            return cls(head)
        except ValueError:
            return cls.TOOL_ERROR


class NotMeasuredError(ValueError):
    """The tool cannot complete this evaluation or job; ``reason`` says which :class:`NotMeasured` kind. A campaign
    records the job as not measured (never as a breach); the Python API raises it (a ``ValueError``: the caller
    asked for something this input or detector cannot give)."""

    def __init__(self, reason: NotMeasured, message: str) -> None:
        super().__init__(message)
        self.reason = NotMeasured(reason)



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
