"""The fixed audit of ``tools/behaviour_rows.py`` gives the rows recorded before the redesign (issue 12).

The rows were written by the code before the perturbation / detector / objective redesign (on the shipped model
v6; the redesign, commit 2eb3dbf, reproduced them) and rewritten once for the shipped model v7 by the same tool
on the redesigned code (the oracle rows stayed identical). Any later change of the worst error, the worst θ, the
evaluation count or the verdict of these searches is a change of behaviour and fails here. Floating-point tolerance: 1e-6 relative on errors, 1e-6 absolute on θ.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("behaviour_rows", ROOT / "tools" / "behaviour_rows.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("config", ["twostage", "single", "oracle"])
def test_audit_rows_unchanged(config):
    tool = _tool()
    golden = json.loads(tool.GOLDEN.read_text())[config]
    rows = tool.audit_rows(config)
    assert [(r["sample_id"], r["method"]) for r in rows] == [(g["sample_id"], g["method"]) for g in golden]
    for r, g in zip(rows, golden, strict=True):
        where = f"{config} {r['sample_id']} {r['method']}"
        assert (r["nfev"], r["nit"], r["verdict"], r["search_status"]) == (
            g["nfev"], g["nit"], g["verdict"], g["search_status"]), where
        assert r["worst_m"] == pytest.approx(g["worst_m"], rel=1e-6), where
        assert r["worst_x"].keys() == g["worst_x"].keys(), where
        for k, v in g["worst_x"].items():
            assert r["worst_x"][k] == pytest.approx(v, abs=1e-6), f"{where} {k}"
