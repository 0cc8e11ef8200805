"""atomic_write: the old file stays whole until the new one is complete; nothing partial is left behind."""

import os

import pytest

from vbl_robust.atomic import atomic_write


def test_a_write_that_fails_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "report.html"
    atomic_write(target, "old report")
    assert target.read_text() == "old report"

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space left"):
        atomic_write(target, "new report " * 1000)
    assert target.read_text() == "old report"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    monkeypatch.undo()
    atomic_write(target, b"\x89PNG bytes")
    assert target.read_bytes() == b"\x89PNG bytes"


def test_a_written_file_gets_the_mode_of_a_plain_open_and_an_error_names_the_target(tmp_path, monkeypatch):
    """mkstemp creates 0600: reports written atomically were unreadable to a colleague sharing the run."""
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    target = atomic_write(tmp_path / "report.html", "r")
    assert target.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OSError) as info:
        atomic_write(target, "new")
    assert info.value.errno == 28 and info.value.filename == str(target)
