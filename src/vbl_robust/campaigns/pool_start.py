"""The first code a local campaign's worker process runs: it ties the worker's life to its parent's before anything
heavy is imported.

A worker is a fresh interpreter (``spawn``) that then imports torch, OpenCV and the detector — seconds, and about a
gigabyte. A parent killed meanwhile (``kill -9``, the machine's out-of-memory killer) must not leave it behind: so
the process's target is :func:`start_worker`, in this module that imports nothing of ours but :mod:`vbl_robust`'s
light package, which asks Linux to kill the worker when its parent dies (``PR_SET_PDEATHSIG``) and then checks that
the parent it was started by is still its parent (a parent that died before that call is not signalled: the
worker was re-parented, and ends at once). Only then are the worker's arguments (pickled by the parent, as bytes)
unpickled and the worker's modules imported (:func:`pool_worker`).
"""

from __future__ import annotations

import os
import sys
from enum import StrEnum
from typing import Any

__all__ = ["Message", "die_with_parent", "pool_worker", "start_worker"]


class Message(StrEnum):
    """What a worker puts on the result queue, as ``(message, value)``: a job's rows to commit, a sample done, or
    the one line of a worker that could not start."""

    ROWS = "rows"
    DONE = "done"
    ERROR = "error"

#: ``prctl`` option: the signal this process gets when its parent thread ends (Linux).
PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """Make this process die with its parent (Linux: ``PR_SET_PDEATHSIG`` = SIGKILL; elsewhere only the check),
    and exit at once when its parent is no longer ``parent`` (the PID the parent gave: it died before the call)."""
    import signal

    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        except (OSError, AttributeError):  # pragma: no cover - a libc without prctl
            pass
    if os.getppid() != parent:
        os._exit(1)  # orphaned during start-up: nothing to clean up, nobody to report to


def start_worker(parent: int, tasks: Any, results: Any, payload: bytes) -> None:
    """Target of a local worker process: :func:`die_with_parent`, then the worker proper with the arguments
    ``payload`` (the pickled ``(detector, settings, run_id)``) on the task and result queues."""
    die_with_parent(parent)
    import pickle

    pool_worker(tasks, results, *pickle.loads(payload))


def pool_worker(tasks: Any, results: Any, detector: Any, settings: Any, run_id: int) -> None:
    """A worker process: one torch thread; runs sample tasks from ``tasks`` until ``None`` and sends each job's
    rows (``("rows", rows)``), then ``("done", None)`` per task; a detector that cannot be built is one line
    (``("error", line)``). Its modules (torch, the detector) are imported here, once :func:`start_worker` has tied
    the process's life to its parent's."""
    import warnings

    from ..constants import TORCH_JIT_WARNING
    from .work import detector_for, one_core, run_sample_task

    warnings.filterwarnings("ignore", message=TORCH_JIT_WARNING, category=FutureWarning)
    one_core()
    try:
        det = detector_for(detector)
    except Exception as exc:  # noqa: BLE001 - reported to the parent as one line, not a traceback
        results.put((Message.ERROR, f"{type(exc).__name__}: {exc}"))
        return
    while (task := tasks.get()) is not None:
        for rows in run_sample_task(task, det, settings, run_id):
            results.put((Message.ROWS, rows))
        results.put((Message.DONE, None))
