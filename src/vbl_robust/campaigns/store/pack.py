"""A packed store: a compact copy of a results store (``VACUUM INTO`` then xz), as a bundle carries it and a GPU
machine sends its part of a campaign back; :func:`restore_store` unpacks one into a run directory."""

from __future__ import annotations

from pathlib import Path

from .core import PACKED, STORE, ResultStore

__all__ = ["PACKED", "pack_store", "restore_store"]


def pack_store(store: ResultStore, path: Path) -> Path:
    """A compact copy of ``store`` at ``path`` (xz): ``VACUUM INTO`` a temporary file (a consistent snapshot even
    while a run writes), then xz. :func:`restore_store` unpacks it."""
    import lzma
    import sqlite3
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d) / STORE
        con = sqlite3.connect(str(store.path))
        try:
            con.execute("VACUUM INTO ?", (str(tmp),))
        finally:
            con.close()
        path.write_bytes(lzma.compress(tmp.read_bytes(), preset=9))
    return path


def restore_store(packed: Path, run: Path) -> bool:
    """Unpack the packed store ``packed`` into the run directory ``run`` if it holds no store yet (an existing
    store is never replaced); True when it did. ``ValueError`` for a file that is not a complete packed store."""
    import lzma

    target = Path(run) / STORE
    if target.exists() or not Path(packed).is_file():
        return False
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(STORE + ".restoring")
    try:
        tmp.write_bytes(lzma.decompress(Path(packed).read_bytes()))
    except (lzma.LZMAError, EOFError) as exc:
        tmp.unlink(missing_ok=True)
        raise ValueError(f"{packed}: not a complete packed store ({exc})") from None
    tmp.replace(target)
    return True
