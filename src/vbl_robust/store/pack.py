"""A packed store: a compact copy of a results store (``VACUUM INTO`` then xz), as a bundle carries it and a GPU
machine sends its part of a campaign back; :func:`restore_store` unpacks one into a run directory.

Both ways are streamed in chunks (xz preset :data:`PACK_PRESET`: about 100 MB of compressor memory, 10 MB to
unpack), so a store of any size is packed and restored in bounded memory.
"""

from __future__ import annotations

from pathlib import Path

from .core import _UNPACK_CHUNK, STORE, ResultStore, unpack

__all__ = ["PACK_PRESET", "pack_store", "restore_store"]

#: xz preset of a packed store: 6 (xz's default) needs ~94 MB to compress where 9 needs ~670 MB, for a file a few
#: per cent larger.
PACK_PRESET = 6


def pack_store(store: ResultStore, path: Path) -> Path:
    """A compact copy of ``store`` at ``path`` (xz): ``VACUUM INTO`` a temporary file (a consistent snapshot even
    while a run writes), then xz, streamed, into a temporary file beside ``path`` that replaces it whole.
    :func:`restore_store` unpacks it."""
    import lzma
    import shutil
    import sqlite3
    import tempfile

    path = Path(path)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d) / STORE
        con = sqlite3.connect(str(store.path))
        try:
            con.execute("VACUUM INTO ?", (str(tmp),))
        finally:
            con.close()
        part = path.with_name(path.name + ".part")
        try:
            with open(tmp, "rb") as src, lzma.open(part, "wb", preset=PACK_PRESET) as dst:
                shutil.copyfileobj(src, dst, _UNPACK_CHUNK)
            part.replace(path)
        finally:
            part.unlink(missing_ok=True)
    return path


def restore_store(packed: Path, run: Path) -> bool:
    """Unpack the packed store ``packed`` into the run directory ``run`` if it holds no store yet (an existing
    store is never replaced), streamed; True when it did. ``ValueError`` for a file that is not a complete packed
    store (nothing is left in ``run``)."""
    target = Path(run) / STORE
    if target.exists() or not Path(packed).is_file():
        return False
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = unpack(Path(packed), target.with_name(STORE + ".restoring"))
    tmp.replace(target)
    return True
