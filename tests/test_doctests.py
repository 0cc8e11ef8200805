"""The examples in the package's docstrings run and print what they say (a renamed or moved name breaks them here,
not in a reader's hands). The PnP modules run their own (tests/pnp)."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import numpy as np
import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
#: NumPy's default print options: the examples print arrays as a reader's fresh interpreter does (ultralytics, once
#: imported by another test, sets a float formatter of its own).
NUMPY_DEFAULTS = {"precision": 8, "threshold": 1000, "edgeitems": 3, "linewidth": 75, "suppress": False,
                  "nanstr": "nan", "infstr": "inf", "formatter": None, "sign": "-", "floatmode": "maxprec"}
#: Modules whose examples another test runs already.
RUN_ELSEWHERE = {"vbl_robust.pnp.differentiable", "vbl_robust.pnp.ippe"}


def _with_examples() -> list[str]:
    out = []
    for path in sorted((SRC / "vbl_robust").rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            name = ".".join(path.relative_to(SRC).with_suffix("").parts).removesuffix(".__init__")
            if name not in RUN_ELSEWHERE:
                out.append(name)
    return out


MODULES = _with_examples()


def test_the_docstrings_hold_examples():
    assert len(MODULES) >= 20 and "vbl_robust.search.zones" in MODULES


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of_a_docstring_run(name):
    module = importlib.import_module(name)
    with np.printoptions(**NUMPY_DEFAULTS):
        result = doctest.testmod(module, report=False, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{result.failed} of {result.attempted} example(s) of {name} failed (run " \
                               f"`python -m doctest -v` on it)"
