"""Where a campaign's samples come from: generated synthetic approaches, or a LARD V2 dataset directory; for a
sequence campaign, generated approach sequences or a LARD V2 directory grouped into sequences."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..specs.kinds import SourceKind
from .provenance import file_sha256

logger = logging.getLogger(__name__)


def find_lard_files(directory: str | Path, *, option: str = "--lard") -> tuple[Path, Path]:
    """The metadata CSV and runway-DB JSON of a LARD V2 dataset directory (searched at the top, then one level
    down); ``ValueError`` naming the candidates when there is not exactly one of each. Messages start with
    ``option`` (the command-line option or argument that named the directory) and the directory."""
    d = Path(directory)
    name = f"{option} {d}".strip()
    if not d.is_dir():
        raise FileNotFoundError(f"{name}: not a directory")
    found: dict[str, list[Path]] = {}
    for pattern, kind in (("*.csv", "csv"), ("*.json", "json")):
        hits = sorted(d.glob(pattern)) or sorted(d.glob(f"*/{pattern}"))
        found[kind] = hits
    for kind, what in (("csv", "metadata CSV"), ("json", "runway database JSON")):
        hits = found[kind]
        if not hits:
            raise FileNotFoundError(f"{name}: no {what} (*.{kind}) found")
        if len(hits) > 1:
            names = ", ".join(str(h.relative_to(d)) for h in hits[:6])
            raise ValueError(f"{name}: several {what} files ({names}); point {option or 'it'} at a directory with "
                             "exactly one")
    return found["csv"][0], found["json"][0]


def load_samples(n: int, seed: int, *, lard: str | Path | None = None, width: int = 1024, height: int = 1024,
                 at_most: bool = False, **read_options: Any) -> tuple[list[Any], dict[str, Any]]:
    """``n`` samples and a description of their source (provenance).

    Synthetic (``lard`` None): ``vbl_robust.scenes.generate(n, seed=seed, width=, height=)``. LARD: all rows of the
    dataset read with :func:`vbl_robust.data.read_lard`, then ``n`` of them drawn at random with ``seed``, kept in
    file order (``ValueError`` when the dataset has fewer than ``n``, unless ``at_most``: then ``n`` was a default
    count, not the user's, and a smaller dataset gives all of its rows, with a warning).
    """
    if n < 1:
        raise ValueError(f"number of images must be >= 1, got {n}")
    if lard is None:
        from ..scenes.generate import generate

        samples = list(generate(n, seed=seed, width=width, height=height))
        return samples, {"kind": SourceKind.SYNTHETIC.value, "n": n, "seed": seed, "width": width, "height": height}
    from ..data.lard_read import read_lard

    csv_path, db_path = find_lard_files(lard)
    allrows = list(read_lard(csv_path, db_path, **read_options))
    if not allrows:
        raise ValueError(f"--lard {lard}: the dataset has no usable rows")
    if n > len(allrows) and at_most:
        logger.warning("--lard %s: the dataset has %d usable rows; all of them are used (the default count is %d)",
                       lard, len(allrows), n)
        n = len(allrows)
    if n > len(allrows):  # never fewer images than asked without a word
        raise ValueError(f"--lard {lard}: {n} images asked for, the dataset has {len(allrows)} usable rows (ask for "
                         f"{len(allrows)} or fewer)")
    idx = np.sort(np.random.default_rng(seed).choice(len(allrows), size=n, replace=False))
    samples = [allrows[i] for i in idx]
    return samples, {"kind": SourceKind.LARD.value, "csv": str(csv_path), "csv_sha256": file_sha256(csv_path), "db": str(db_path),
                     "db_sha256": file_sha256(db_path), "rows": len(allrows), "n": len(samples), "seed": seed,
                     "options": {k: str(v) for k, v in read_options.items()}}


def load_sequences(source: str | Path, *, frames: int, rate_hz: float, seed: int, width: int = 1024,
                   height: int = 1024) -> tuple[list[Any], dict[str, Any]]:
    """The samples of a sequence campaign and their source (provenance): ``source`` a count N (N generated
    approach sequences of ``frames`` frames at ``rate_hz``, :func:`vbl_robust.scenes.sequences.generate_sequences`) or a
    LARD V2 dataset directory grouped into sequences (:func:`vbl_robust.data.read_lard_sequences`; ``rate_hz``
    gives the times of data without them). ``ValueError`` / ``FileNotFoundError`` with one line naming
    ``--sequences`` for bad input."""
    text = str(source).strip()
    if text.isdigit():
        from ..scenes.sequences import generate_sequences

        n = int(text)
        if n < 1:
            raise ValueError(f"--sequences {source}: need at least 1 sequence")
        seqs = generate_sequences(n, frames, rate_hz, seed, width=width, height=height)
        return seqs, {"kind": SourceKind.SYNTHETIC_SEQUENCES.value, "n": n, "frames": frames, "rate_hz": rate_hz, "seed": seed,
                      "width": width, "height": height}
    if not Path(text).is_dir():
        raise ValueError(f"--sequences {source}: expected a number of sequences or a LARD V2 dataset directory")
    from ..data.sequence import read_lard_sequences

    csv_path, db_path = find_lard_files(text)
    seqs = read_lard_sequences(csv_path, db_path, rate_hz=rate_hz)
    if not seqs:
        raise ValueError(f"--sequences {source}: the dataset has no usable rows")
    return seqs, {"kind": SourceKind.LARD_SEQUENCES.value, "csv": str(csv_path), "csv_sha256": file_sha256(csv_path),
                  "db": str(db_path), "db_sha256": file_sha256(db_path), "sequences": len(seqs), "rate_hz": rate_hz}
