"""A door for any detector: ``--detector-plugin MODULE:FACTORY`` (or ``path/to/file.py:FACTORY``).

The factory is called with no argument and returns an object that satisfies the :class:`~vbl_robust.detect.base.Detector`
protocol (:mod:`vbl_robust.detect.base`): the capabilities ``input_size``, ``uses_pixels`` and ``differentiable``
declared, a ``detect(context)`` returning one :class:`~vbl_robust.detect.Detections` per row of the context, and
``detect_top(context)`` when it says it is differentiable (then APGD can run on it).

Importing a plug-in runs its code: naming it on the command line is the user's consent; a plug-in named by data (a
stored run, a bundle, a ``--config`` file) is imported only with ``--trust-model``
(:func:`~vbl_robust.consent.consent_needed`). Its identity in the store and the report is the plug-in's
name, the SHA-256 of its source file (so two versions of it never mix in one store) and, where the user gives one
(``--plugin-digest``), the digest of its weights. A plug-in that does not satisfy the protocol is refused in one
line when it is built; one that raises on the run's first image is refused before the run
(:func:`vbl_robust.campaigns.precheck.check_run`); an exception inside it during a run makes that job *not
measured* (a detector error), never a breach.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import re
import sys
from pathlib import Path
from typing import Any

__all__ = ["CAPABILITIES", "build_plugin", "parse_plugin", "plugin_source"]

#: The capabilities a detector declares (read as declared, never guessed): :mod:`vbl_robust.detect.base`.
CAPABILITIES = ("input_size", "uses_pixels", "differentiable")
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def parse_plugin(target: str, option: str = "--detector-plugin") -> tuple[str, str]:
    """``(module or file, factory)`` of ``MODULE:FACTORY`` / ``FILE.py:FACTORY``; ``ValueError`` (one line naming
    ``option``) for anything else. Nothing is imported."""
    where, sep, attr = str(target).rpartition(":")
    if not sep or not _NAME.match(attr):
        raise ValueError(f"{option} {target}: expected MODULE:FACTORY or path/to/file.py:FACTORY")
    if where.endswith(".py"):
        if not Path(where).is_file():
            raise ValueError(f"{option} {target}: no file {where}")
        return str(Path(where).resolve()), attr
    if not _MODULE.match(where):
        raise ValueError(f"{option} {target}: {where!r} is neither a module name nor a .py file")
    return where, attr


def plugin_source(target: str) -> Path | None:
    """The source file of the plug-in ``target`` (its identity hashes it), without importing it where it can: a
    ``.py`` path as it is; a top-level module through its import spec (a submodule's parent package is imported to
    find it). None when it cannot be found."""
    where, _ = parse_plugin(target)
    if where.endswith(".py"):
        return Path(where)
    try:
        spec = importlib.util.find_spec(where)
    except (ImportError, ValueError):
        return None
    return Path(spec.origin) if spec is not None and spec.origin and Path(spec.origin).is_file() else None


def _import(where: str) -> Any:
    if not where.endswith(".py"):
        return importlib.import_module(where)
    name = "vbl_robust_plugin_" + hashlib.sha256(where.encode()).hexdigest()[:16]  # the same in every process
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, where)
    if spec is None or spec.loader is None:
        raise ValueError(f"{where}: not a Python file that can be imported")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # a worker that unpickles the plug-in's objects finds the module again
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def build_plugin(target: str) -> Any:
    """Import the plug-in ``target`` and call its factory; ``ValueError`` (one line) when it cannot be imported, the
    factory is missing or raises, or what it returns does not satisfy the detector protocol (a ``detect`` method,
    the declared capabilities, ``detect_top`` when it says it is differentiable)."""
    where, attr = parse_plugin(target)
    shown = Path(where).name if where.endswith(".py") else where
    try:
        module = _import(where)
    except Exception as exc:  # noqa: BLE001 - any failure to import the user's code is one line
        raise ValueError(f"--detector-plugin {target}: importing {shown} failed ({type(exc).__name__}: {exc})") \
            from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ValueError(f"--detector-plugin {target}: {shown} has no callable {attr!r}")
    try:
        detector = factory()
    except Exception as exc:  # noqa: BLE001
        raise ValueError(f"--detector-plugin {target}: {attr}() raised {type(exc).__name__}: {exc}") from None
    missing = [c for c in CAPABILITIES if not hasattr(detector, c)]
    if not callable(getattr(detector, "detect", None)):
        missing.insert(0, "detect(context)")
    if getattr(detector, "differentiable", False) and not callable(getattr(detector, "detect_top", None)):
        missing.append("detect_top(context) (it says it is differentiable)")
    if missing:
        raise ValueError(f"--detector-plugin {target}: what {attr}() returns ({type(detector).__name__}) is not a "
                         f"detector: it lacks {', '.join(missing)} (the protocol: vbl_robust.detect.base)")
    return detector
