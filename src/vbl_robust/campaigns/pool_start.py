"""The first code a local campaign's worker process runs: it ties the worker's life to its parent's before anything
heavy is imported.

A worker is a fresh interpreter (``spawn``) that then imports torch, OpenCV and the detector — seconds, and about a
gigabyte. A parent killed meanwhile (``kill -9``, the machine's out-of-memory killer) must not leave it behind: so
the process's target is :func:`start_worker`, in this module that imports nothing of ours but :mod:`vbl_robust`'s
light package, which asks Linux to kill the worker when its parent dies (``PR_SET_PDEATHSIG``) and then checks that
the parent it was started by is still its parent (a parent that died before that call is not signalled: the
worker was re-parented, and ends at once). Only then are the worker's arguments (pickled by the parent, as bytes)
unpickled and the worker imported (:func:`vbl_robust.campaigns.runner._pool_worker`).
"""

from __future__ import annotations

import os
import sys
from typing import Any

__all__ = ["die_with_parent", "start_worker"]

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

    from .runner import _pool_worker

    _pool_worker(tasks, results, *pickle.loads(payload))
