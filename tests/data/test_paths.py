"""resolve_within keeps dataset paths inside their root."""

from __future__ import annotations

import pytest

from vbl_robust.data.paths import resolve_within


def test_inside_paths_resolve(tmp_path):
    assert resolve_within(tmp_path, "a/b.png") == (tmp_path / "a" / "b.png").resolve()
    assert resolve_within(tmp_path, "./a/./b.png") == (tmp_path / "a" / "b.png").resolve()
    assert resolve_within(tmp_path, "a\\b.png") == (tmp_path / "a" / "b.png").resolve()


@pytest.mark.parametrize("bad, match", [
    ("", "empty path"), ("   ", "empty path"), ("/abs/x.png", "absolute"), ("C:/x.png", "absolute"),
    ("\\\\server\\share\\x.png", "absolute"), ("..", r"contains '\.\.'"), ("a/../../x", r"contains '\.\.'"),
    ("a\\..\\x", r"contains '\.\.'"),
])
def test_escapes_are_rejected(tmp_path, bad, match):
    with pytest.raises(ValueError, match=f"^ctx: .*{match}|^ctx: {match}"):
        resolve_within(tmp_path, bad, context="ctx")


def test_symlink_out_is_rejected_but_inside_link_is_fine(tmp_path):
    root = tmp_path / "root"
    (root / "real").mkdir(parents=True)
    (root / "inner").symlink_to(root / "real", target_is_directory=True)
    (root / "outer").symlink_to(tmp_path, target_is_directory=True)
    assert resolve_within(root, "inner/x.png") == (root / "real" / "x.png").resolve()
    with pytest.raises(ValueError, match="outside the dataset root"):
        resolve_within(root, "outer/x.png")
