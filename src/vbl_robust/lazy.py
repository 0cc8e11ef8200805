"""Lazy public names for a package: ``import vbl_robust.x`` stays cheap, the heavy parts load on first use.

One helper for every package that re-exports names from heavy submodules (torch, ultralytics, onnxruntime): the
command line's ``--help`` and the registries must not import them.

>>> import vbl_robust as vr             # imports no torch; vr.Sample imports its module on first use
>>> vr.Sample.__module__
'vbl_robust.data.sample'
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_names"]


def lazy_names(package: str, names: Mapping[str, str | tuple[str, None]], namespace: dict[str, Any],
               public: list[str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package``.

    Args:
        package: the package's ``__name__``.
        names: public name → the module that defines it (``".sub"`` relative to ``package``, or absolute), or
            ``(module, None)`` for the module itself.
        namespace: the package's ``globals()`` (a resolved name is stored there, so it is looked up once).
        public: the package's ``__all__``.
    """

    def __getattr__(name: str) -> Any:
        """The public name ``name``, imported from its submodule on first use."""
        try:
            target = names[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        module, attr = (target, name) if isinstance(target, str) else target
        mod = importlib.import_module(module, package)
        value = mod if attr is None else getattr(mod, attr)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(public)

    return __getattr__, __dir__
