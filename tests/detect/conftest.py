"""Fixtures for detector tests: tiny untrained YOLO-pose checkpoints."""

from __future__ import annotations

import pytest
from detect_helpers import _save_pose_ckpt


@pytest.fixture(scope="session")
def tiny_pose_pt(tmp_path_factory):
    return _save_pose_ckpt(tmp_path_factory.mktemp("models") / "tiny_pose.pt")


@pytest.fixture(scope="session")
def make_pose_ckpt(tmp_path_factory):
    def make(name, **kw):
        return _save_pose_ckpt(tmp_path_factory.mktemp("models") / name, **kw)

    return make
