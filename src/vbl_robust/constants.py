"""The numbers and vocabularies every part of vbl-robust shares, defined once.

- ``EPS_SAFE_M``: the safety threshold ε_safe (metres): a box is safe iff ``max_Θ L ≤ EPS_SAFE_M``.
- ``CONF_THRESHOLD``: the operational confidence threshold τ_conf of the selection σ_select.
- ``PENALTY_M``: the error ``L`` assigned to any failed evaluation (metres; the paper's detection-breakdown value).
- :class:`FailureReason` (``FAILURE_REASONS``: its codes with their meaning): why one evaluation of the pipeline
  under test failed (a *flagged* failure of the pipeline, penalised with ``PENALTY_M``).
- :class:`NotMeasured`: why the *tool* could not complete a job (an input missing, a method that cannot run on this
  model, an exception in our code or in the detector) — not a finding about the pipeline; :class:`NotMeasuredError`
  carries it. The line between the two kinds of failure is drawn here, once: a :class:`FailureReason` is
  the pipeline's and counts against it, a :class:`NotMeasured` reason is the tool's and enters no rate.
- :class:`Verdict`: the answer for one image and box, used by search, campaigns and report alike.
- :class:`BreachKind`: what kind of failure a breach is — flagged (the system knows it has no fix) or hazardously
  misleading (a confident pose far off).

This module imports nothing of the package, so every part (``search/`` included) may import it.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["CONF_THRESHOLD", "EPS_SAFE_M", "FAILURE_REASONS", "PENALTY_M", "TARGETS", "BreachKind", "FailureReason",
           "NotMeasured", "NotMeasuredError", "Verdict"]

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

class FailureReason(StrEnum):
    """Why an evaluation of the pipeline under test failed; the value is the code stored with each evaluation
    (``""`` is a success), :attr:`meaning` says what it means. Each is a *flagged* failure of the pipeline: the
    system knows it has no fix, and it counts against the pipeline. A failure of the tool (the pixels cannot be
    loaded, a method that cannot run on the detector) is none of these: it is :class:`NotMeasured`. Both answer
    :attr:`flagged` and :attr:`not_measured`: the line between the two kinds of failure, drawn here once."""

    NO_DETECTION = "no_detection"
    LOW_CONFIDENCE = "low_confidence"
    NON_FINITE_KEYPOINTS = "non_finite_keypoints"
    PNP_FAILED = "pnp_failed"
    NON_FINITE_POSITION = "non_finite_position"
    OUT_OF_VIEW = "out_of_view"
    MONITOR_REJECTED = "monitor_rejected"

    @property
    def meaning(self) -> str:
        """What the code means, in one line (the report's legend)."""
        return _MEANINGS[self]

    @property
    def flagged(self) -> bool:
        """A failure of the pipeline under test that it knows of (availability lost): always, for these."""
        return True

    @property
    def not_measured(self) -> bool:
        """A failure of the tool, entering no rate: never, for these (see :class:`NotMeasured`)."""
        return False


_MEANINGS = {
    FailureReason.NO_DETECTION: "the detector returned no candidate",
    FailureReason.LOW_CONFIDENCE: "the best candidate's confidence is below τ_conf",
    FailureReason.NON_FINITE_KEYPOINTS: "the selected keypoints are not finite",
    FailureReason.PNP_FAILED: "the PnP solver found no pose",
    FailureReason.NON_FINITE_POSITION: "the PnP position is not finite",
    FailureReason.OUT_OF_VIEW: "the perturbation turned the runway out of the camera's view (a corner behind the "
                               "camera)",
    FailureReason.MONITOR_REJECTED: "a runtime monitor rejected the pose (its PnP reprojection residual, or its "
                                    "corners' σ propagated to the position, above the monitor's limit)",
}

#: Each :class:`FailureReason`'s code with what it means.
FAILURE_REASONS: dict[str, str] = {r.value: r.meaning for r in FailureReason}


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

    @property
    def flagged(self) -> bool:
        """A failure of the pipeline under test: never, for these (see :class:`FailureReason`)."""
        return False

    @property
    def not_measured(self) -> bool:
        """A failure of the tool, entering no rate: always, for these."""
        return True


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
