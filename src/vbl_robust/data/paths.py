"""Confining dataset-relative paths to their dataset root."""

from __future__ import annotations

from pathlib import Path, PurePosixPath, PureWindowsPath


def resolve_within(root: str | Path, relative: str, *, context: str = "") -> Path:
    """Resolve ``relative`` (a path string from a dataset file) under ``root``; refuse anything that leaves it.

    Rejected with a one-line ``ValueError`` (prefixed by ``context``): empty paths and paths naming the root
    itself (``"."``), control characters (NUL, newline, …), absolute paths (POSIX or Windows drive/UNC), any
    ``..`` component, and paths whose resolved location (following symlinks) is outside the resolved root or
    cannot be resolved (symlink loop). The file need not exist.

    Returns:
        The resolved absolute path.
    """
    prefix = f"{context}: " if context else ""
    text = str(relative).strip()
    if not text:
        raise ValueError(f"{prefix}empty path")
    if PurePosixPath(text).is_absolute() or PureWindowsPath(text).is_absolute() or PureWindowsPath(text).drive:
        raise ValueError(f"{prefix}path {text!r} is absolute; it must be relative to the dataset root {root}")
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in text):
        raise ValueError(f"{prefix}path {text!r} contains control characters")
    parts = text.replace("\\", "/").split("/")
    if ".." in parts:
        raise ValueError(f"{prefix}path {text!r} contains '..'; it must stay inside the dataset root {root}")
    if all(part in ("", ".") for part in parts):
        raise ValueError(f"{prefix}path {text!r} names the dataset root {root} itself, not a file in it")
    try:
        base = Path(root).resolve()
        resolved = (base / text.replace("\\", "/")).resolve()
    except (OSError, RuntimeError) as exc:  # RuntimeError: symlink loop (Python < 3.13)
        raise ValueError(f"{prefix}path {text!r} cannot be resolved under {root} ({exc})") from None
    if resolved == base or not resolved.is_relative_to(base):
        raise ValueError(f"{prefix}path {text!r} resolves to {resolved}, outside the dataset root {base} (symlink?)")
    return resolved
