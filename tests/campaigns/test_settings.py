"""The pipeline settings, declared once: what they write, what they read back, what they refuse."""

from __future__ import annotations

import dataclasses
import json

import pytest

from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box
from vbl_robust.specs.settings import WRITTEN_WHEN_SET, PipelineSettings

BLOCK = Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=4),))
#: A campaign as the first stores wrote it: the five first settings beside the name, seed and blocks, nothing else.
FIRST_STORES = {"eps_safe_m": 1000.0, "penalty_m": 5000.0, "conf_threshold": 0.25, "pnp": "ippe_lm", "lipschitz": None}


def test_unset_later_settings_are_not_written_so_earlier_keys_stay():
    assert PipelineSettings().to_dict() == FIRST_STORES
    assert set(dataclasses.asdict(PipelineSettings())) == set(FIRST_STORES) | set(WRITTEN_WHEN_SET)
    later = PipelineSettings(clock="process", sustain=3)
    assert later.to_dict() == {**FIRST_STORES, "clock": "process", "sustain": 3}
    assert CampaignSpec("t", (BLOCK,)).context("d") != CampaignSpec("t", (BLOCK,), settings=later).context("d")


def test_the_stored_campaign_keeps_its_settings_at_the_top_level_and_reads_them_back():
    spec = CampaignSpec("t", (BLOCK,), seed=3, settings=PipelineSettings(eps_safe_m=40.0, lipschitz=(2.0,),
                                                                          monitor_px=1.5))
    stored = json.loads(json.dumps(spec.to_dict()))
    assert list(stored)[:2] == ["name", "seed"] and stored["eps_safe_m"] == 40.0 and stored["monitor_px"] == 1.5
    assert "settings" not in stored and "clock" not in stored
    back = CampaignSpec.from_dict(stored)
    assert back == spec and back.settings.lipschitz == (2.0,)  # a JSON list comes back a tuple
    old = {"name": "t", "seed": 0, **FIRST_STORES, "notes": "", "figures": [], "blocks": stored["blocks"]}
    assert CampaignSpec.from_dict(old).settings == PipelineSettings()


def test_with_settings_changes_one_setting_and_checks_it():
    spec = CampaignSpec("t", (BLOCK,))
    assert spec.with_settings(clock="process").settings == PipelineSettings(clock="process")
    assert spec.settings.clock == "wall"  # frozen: the original is unchanged
    with pytest.raises(ValueError, match="--monitor-residual must be a finite number of pixels > 0, got -1.0"):
        spec.with_settings(monitor_px=-1.0)


@pytest.mark.parametrize(("changes", "message"), [
    ({"clock": "gpu"}, "clock must be one of"),
    ({"sustain": 0}, "sustain: need an integer >= 1"),
    ({"sustain": True}, "sustain: need an integer >= 1"),
    ({"monitor_sigma_m": float("nan")}, "--monitor-sigma must be a finite number of metres > 0"),
    ({"monitor_px": 2.0, "sustain": 2}, "--monitor-residual applies to image campaigns"),
    ({"monitor_sigma_m": 2.0, "sustain": 2}, "--monitor-sigma applies to image campaigns"),
])
def test_settings_the_pipeline_cannot_run_are_refused_in_one_line(changes, message):
    with pytest.raises(ValueError, match=message):
        PipelineSettings(**changes)


def test_a_campaign_takes_its_settings_as_one_record():
    with pytest.raises(TypeError, match="settings must be a PipelineSettings"):
        CampaignSpec("t", (BLOCK,), settings={"eps_safe_m": 40.0})
    with pytest.raises(TypeError):
        CampaignSpec("t", (BLOCK,), eps_safe_m=40.0)
    pnp = Block(kind="pnp")
    with pytest.raises(ValueError, match="a sequence campaign"):
        CampaignSpec("t", (pnp,), settings=PipelineSettings(sustain=2))
