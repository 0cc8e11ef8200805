"""What makes two runs parts of one campaign, as a store compares them: the campaign spec (its presentation keys
aside) and the detector's identity (:func:`detector_identity`); a difference is refused in one line naming the
first differing setting (:func:`check_same`)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .rows import StoredCampaign

#: Keys of a campaign spec that only change how results are shown (the report's figures): they never make a
#: store refuse a run, and the newer value is recorded.
PRESENTATION_KEYS = ("figures",)


def check_same(path: str | Path, have: StoredCampaign, spec: Mapping[str, Any], detector: Mapping[str, Any], *,
               hint: str = "rerun with the same options to resume, or use another --out") -> None:
    """``ValueError`` (naming the store ``path`` and the first difference, then ``hint``) unless the stored campaign
    ``have`` has the settings ``spec`` (a spec's dict) and the detector ``detector``."""
    def shown(d: Mapping[str, Any]) -> str:
        return json.dumps({k: v for k, v in d.items() if k not in PRESENTATION_KEYS}, sort_keys=True)

    if shown(have.stored_spec) != shown(spec):
        diff = first_difference(have.stored_spec, dict(spec))
        raise ValueError(f"{path}: holds campaign {have.name!r} with other settings ({diff}); {hint}")
    mine, theirs = detector_identity(have.detector), detector_identity(detector)
    if mine != theirs:
        diff = first_difference(mine, theirs)
        name, sha = have.detector.get("name"), have.detector.get("sha256")
        held = f"{name!r}" + (f" (sha256 {str(sha)[:12]}…)" if sha else "")
        other = "the same detector with other options" if detector.get("name") == name else repr(detector.get("name"))
        raise ValueError(f"{path}: holds results of detector {held}, not of {other} ({diff}); "
                         + ("use another --out" if hint.startswith("rerun") else hint))


def detector_identity(detector: Mapping[str, Any]) -> dict[str, Any]:
    """What decides a detector's outputs, as a store compares it: its kind, model SHA-256 and options (design,
    oracle noise, crop window, …) — not the engine or device, which change speed and outputs by ≤ 1e-3 px only, so
    a run may resume or merge across them (CPU and GPU, ONNX Runtime and torch)."""
    options = {k: v for k, v in (detector.get("options") or {}).items() if k not in ("engine", "device")}
    return {"kind": detector.get("kind"), "sha256": detector.get("sha256"), "options": options}


def first_difference(a: Any, b: Any, path: str = "") -> str:
    """Human-readable location of the first difference between two JSON values."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if a.get(k) != b.get(k):
                return first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return first_difference(x, y, f"{path}[{i}]")
    return f"{path or 'spec'}: stored {json.dumps(a)[:80]} vs now {json.dumps(b)[:80]}"
