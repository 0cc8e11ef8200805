"""Stable identities: canonical JSON, its SHA-256 digest, and the SHA-256 of a file.

Job keys, detector identities and dataset fingerprints are digests of :func:`canonical_json`, so the same
content always gives the same key (``15.0`` and ``15`` alike; non-finite floats as strings).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vbl_robust.space import ParameterBox

__all__ = ["canonical_json", "digest", "file_sha256"]


def canonical_json(obj: Any) -> str:
    """Deterministic JSON (sorted keys, no spaces, non-finite floats as strings) used for keys and hashes."""
    return json.dumps(_plain(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def _plain(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    if isinstance(v, ParameterBox):
        return _plain(v.to_dict())
    if hasattr(v, "item") and not isinstance(v, str):  # numpy scalars
        v = v.item()
    if isinstance(v, float):
        if not math.isfinite(v):
            return repr(v)
        return int(v) if v.is_integer() and abs(v) < 2**53 else v  # 15.0 and 15 give the same key
    return v


def digest(obj: Any, n: int = 64) -> str:
    """Hex SHA-256 (first ``n`` characters) of :func:`canonical_json` of ``obj``."""
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:n]


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()
