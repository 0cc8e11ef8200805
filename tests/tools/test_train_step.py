"""``tools/train_step.py``: every step's arguments are ``train()``'s or ultralytics' (its ``**overrides``), and a chained
step finds (or names) its start."""

from __future__ import annotations

import inspect

import pytest

from vbl_robust.detect.shipped import DEFAULT_MODEL
from vbl_robust.detect.train import train


def test_every_step_passes_only_train_or_ultralytics_arguments(script):
    tool = script("tools/train_step.py")
    from ultralytics.cfg import DEFAULT_CFG_DICT

    accepted = (set(inspect.signature(train).parameters) - {"overrides"}) | set(DEFAULT_CFG_DICT)
    for step, (epochs, kwargs) in tool.STEPS.items():
        assert epochs >= 1, step
        assert not set({**tool.COMMON, **kwargs}) - accepted, step
    assert set(tool.INIT) <= set(tool.STEPS) and all(src in tool.STEPS for src, _ in tool.INIT.values())


def test_a_chained_step_starts_from_its_source_epoch_or_says_which_to_run(script, tmp_path, monkeypatch):
    tool = script("tools/train_step.py")
    monkeypatch.chdir(tmp_path)
    assert tool.init_weights("q") == DEFAULT_MODEL
    with pytest.raises(SystemExit, match=r"step_q/stage00/weights/epoch0\.pt .*run step q first"):
        tool.init_weights("r")
    ckpt = tmp_path / "train_runs/step_q/stage00/weights/epoch0.pt"
    ckpt.parent.mkdir(parents=True)
    ckpt.write_bytes(b"")
    assert tool.init_weights("r").resolve() == ckpt.resolve()


def test_a_step_on_another_steps_data_links_its_rendered_dataset(script, tmp_path, monkeypatch):
    tool = script("tools/train_step.py")
    monkeypatch.chdir(tmp_path)
    assert set(tool.DATA) <= set(tool.STEPS) and set(tool.DATA.values()) <= set(tool.STEPS)
    with pytest.raises(SystemExit, match="run step s first"):
        tool.share_dataset("t", tmp_path / "train_runs/step_t")
    data = tmp_path / "train_runs/step_s/dataset_320px_x"
    (data / "images").mkdir(parents=True)
    tool.share_dataset("t", tmp_path / "train_runs/step_t")
    tool.share_dataset("t", tmp_path / "train_runs/step_t")  # again (a resumed step): nothing to do
    linked = tmp_path / "train_runs/step_t/dataset_320px_x"
    assert linked.is_symlink() and (linked / "images").is_dir()
    tool.share_dataset("q", tmp_path / "train_runs/step_q")  # a step on its own data: nothing linked
    assert not (tmp_path / "train_runs/step_q").exists()
