"""Whether building a detector runs code that is not this package's, and the one refusal that says so.

A detector is named by a :class:`DetectorKind` and, for some kinds, a path: a user's ``.pt`` (a pickle: loading
it runs code), an ``.onnx`` file (a graph of operators: no code) or a ``"module:callable"`` (a factory or a
plug-in: imported and called). Stores, bundles and config files record such identities; building one they name
is running code they name, so it needs the user's consent (``--trust-model``), never a value read from the data
itself (:func:`consent_needed`, :func:`refuse_without_consent`). This module sits on the ground floor, torch-free,
so that what reads a store (``merge``, ``report``) decides without importing any detector.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from pathlib import Path
from typing import Any

__all__ = ["CODE_KINDS", "DETECTOR_KINDS", "PACKAGE_DIR", "PICKLE", "DetectorKind", "consent_needed", "packaged",
           "refuse_untrusted", "refuse_without_consent"]


class DetectorKind(StrEnum):
    """What a :class:`~vbl_robust.detect.shipped.DetectorSpec` builds; the value is the ``kind`` its identity records (a store's bytes).

    ``ORACLE`` projects the ground truth; ``DEFAULT`` is a shipped model; ``ULTRALYTICS`` / ``ONNX`` a user's
    ``.pt`` / ``.onnx`` file; ``FACTORY`` / ``PLUGIN`` name code, ``"module:callable"``. Here, below the detectors,
    so that what reads a store (a report, a merge) knows what a recorded detector is without importing one.
    """

    ORACLE = "oracle"
    DEFAULT = "default"
    ULTRALYTICS = "ultralytics"
    ONNX = "onnx"
    FACTORY = "factory"
    PLUGIN = "plugin"

    @property
    def runs_code(self) -> bool:
        """The spec names code: building the detector imports the module and calls the callable with the spec's
        options (a factory: tests and the Python API; a plug-in: ``--detector-plugin``). Only with the user's
        consent when the spec comes from data (:func:`consent_needed`)."""
        return self in (DetectorKind.FACTORY, DetectorKind.PLUGIN)

    @property
    def model_file(self) -> bool:
        """The spec's ``path`` is a user's model file (it must exist)."""
        return self in (DetectorKind.ULTRALYTICS, DetectorKind.ONNX)

    @property
    def pose_model(self) -> bool:
        """A pose model of ours or a user's: run by an engine on a device, both recorded in its identity."""
        return self in (DetectorKind.DEFAULT, DetectorKind.ULTRALYTICS, DetectorKind.ONNX)

    @property
    def default_engine(self) -> str:
        """What runs a model of this kind's black-box forwards unless told otherwise (:mod:`vbl_robust.detect.engines`)."""
        return "onnxruntime" if self == DetectorKind.ONNX else "torch"


#: The values of :class:`DetectorKind`, in order.
DETECTOR_KINDS = tuple(k.value for k in DetectorKind)
#: Kinds whose spec names code (:attr:`DetectorKind.runs_code`).
CODE_KINDS = tuple(k for k in DetectorKind if k.runs_code)
#: What a ``.pt`` outside the package is (the reason every refusal of one gives).
PICKLE = "a .pt file is a pickle that runs code when loaded"
#: The installed package: the models shipped in it are trusted as its code is.
PACKAGE_DIR = Path(__file__).resolve().parent


def refuse_untrusted(what: str | Path, trust: bool) -> None:
    """Unless ``trust``, ``ValueError`` naming ``what``: a ``.pt`` file is a pickle, and loading it runs code (the
    one refusal every command gives; ``--trust-model``)."""
    if not trust:
        raise ValueError(f"{what}: {PICKLE}; pass --trust-model if you trust it")


def packaged(path: str | Path) -> bool:
    """``path`` lies inside the installed package (the shipped models: trusted as its code is)."""
    try:
        return Path(path).resolve().is_relative_to(PACKAGE_DIR)
    except (OSError, RuntimeError, TypeError, ValueError):  # a path that cannot be resolved is not the package's
        return False


def consent_needed(detector: Any) -> str | None:
    """Why building ``detector`` would run code that is not this package's, in one line; None when it would not.

    The one place that decides it, for a :class:`~vbl_robust.detect.shipped.DetectorSpec` or an identity as a store records it
    (:meth:`~vbl_robust.detect.shipped.DetectorSpec.identity`: a campaign, a bundle's packed store, a file). Code is run by a kind of
    :data:`CODE_KINDS` (its ``"module:callable"`` is imported and called with the stored options) and by a ``.pt``
    outside the package (a pickle: loading it runs code). The shipped models, the oracle and an ONNX file (a graph
    of operators, no code) need no consent. What gives consent is the caller's: ``--trust-model`` on the command
    line (:func:`refuse_without_consent`), never a value read from the data itself.
    """
    if isinstance(detector, Mapping):
        kind = detector.get("kind")
        path = detector.get("factory") if kind in CODE_KINDS else detector.get("path")
    elif hasattr(detector, "kind") and hasattr(detector, "path"):  # a DetectorSpec (one floor up: not imported)
        kind, path = detector.kind, detector.path
    else:
        raise TypeError(f"a DetectorSpec or a detector identity (a mapping), not {type(detector).__name__}")
    if kind in CODE_KINDS:
        module, _, attr = str(path).partition(":")
        return (f"detector {kind} {path!r} is code: building it imports module {module!r} and calls {attr!r} "
                "with the stored options")
    if kind == DetectorKind.ULTRALYTICS and (not path or not packaged(path)):
        return f"{path}: {PICKLE}"
    return None


def refuse_without_consent(detector: Any, trust: bool, *, where: str = "") -> None:
    """Unless ``trust`` (``--trust-model``), ``ValueError`` when :func:`consent_needed` says building ``detector``
    runs code: one line, ``where`` first (e.g. ``"RUN: "``), the reason, and the flag that gives consent."""
    reason = None if trust else consent_needed(detector)
    if reason:
        raise ValueError(f"{where}{reason}; pass --trust-model if you trust it")
