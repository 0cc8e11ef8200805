"""The campaigns' vocabularies as enums, on the ground floor of :mod:`vbl_robust.campaigns` (every module of the
package may import them). Each value is the string stored in the results store; a member compares equal to it, so
stored bytes and job keys do not depend on whether a reader holds the enum or the string.

- :class:`JobKind`: what a job computes (a block's and a row's ``kind``);
- :class:`Role`: what a block is for (a block's and a row's ``role``);
- :class:`JobStatus`: how a job ended; :class:`RunStatus`: where a run stands;
- :class:`SourceKind`: where a run's samples came from.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["JobKind", "JobStatus", "Role", "RunStatus", "SourceKind"]


class JobKind(StrEnum):
    """What a job computes; the value is the string stored in a job's ``kind`` column and key.

    - ``SEARCH``: a worst-case search over one box;
    - ``PNP``: the PnP-solver comparison of one image;
    - ``RISK``: a failure-probability estimate (:mod:`vbl_robust.risk`; methods ``mc`` / ``guided``,
      options the distribution, τ and δ).
    """

    SEARCH = "search"
    PNP = "pnp"
    RISK = "risk"


class Role(StrEnum):
    """The role of a block (and its jobs); the value is the string stored in a job's ``role`` column and key.

    - ``MAIN``: the compared searches;
    - ``REFERENCE``: a dense grid, the true worst case;
    - ``LANDSCAPE``: a dense grid on a few images for the heat map.
    """

    MAIN = "main"
    REFERENCE = "reference"
    LANDSCAPE = "landscape"


class JobStatus(StrEnum):
    """How a job ended: searched (``DONE``), not measured (``NOT_MEASURED``: the tool could not complete it, the
    row's ``reason`` says why, :class:`~vbl_robust.constants.NotMeasured`), or implied by a breach in a chain.
    Stores written before the name read their ``"failed"`` as ``NOT_MEASURED``."""

    DONE = "done"
    NOT_MEASURED = "not measured"
    IMPLIED = "implied"

    @classmethod
    def _missing_(cls, value: object) -> JobStatus | None:
        return cls.NOT_MEASURED if value == "failed" else None


class RunStatus(StrEnum):
    """Where a run stands (the stored strings are the values)."""

    RUNNING = "running"  #: begun, not ended (or ended without recording it: closed as KILLED by the next writer)
    FINISHED = "finished"  #: every planned job is stored
    INCOMPLETE = "incomplete"  #: ended normally with planned jobs left (e.g. a chain stopped early)
    INTERRUPTED = "interrupted"  #: ended by an exception or Ctrl-C
    KILLED = "killed"  #: found still "running" by a later writer: SIGKILL, a machine's or session's end
    UNKNOWN = "unknown"  #: a merged run whose source held its jobs but not its run row


class SourceKind(StrEnum):
    """Where a run's samples came from: the ``kind`` of its dataset source (provenance)."""

    SYNTHETIC = "synthetic"
    LARD = "lard"
    SYNTHETIC_SEQUENCES = "synthetic sequences"
    LARD_SEQUENCES = "lard sequences"
    TRUTH = "truth"  #: the samples of another run, checked against their dense grid (``vbl-robust truth``)
