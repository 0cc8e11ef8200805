"""Each payload class reads back what it writes, key for key (the stored JSON is what the reader sees), reads an older
row's missing keys as None, and gives None for a row without its payload."""

import json
from types import SimpleNamespace

import pytest

from vbl_robust.store.payloads import (
    Nominal,
    RiskPayload,
    RiskStratum,
    SequenceFacts,
    SequenceFrames,
    SequencePayload,
    WorstPayload,
    WorstPoint,
)


def _row(payload):
    return SimpleNamespace(payload=None if payload is None else json.loads(json.dumps(payload)))


def _facts(**kw):
    summary = {"sequence_id": "q0", "sustain": 2, "frames": 3, "roll_deg": 1.5, "sustained_m": 1200.0,
               "window_start": 0, "breached_frames": 2, "longest_run_frames": 2, "longest_run_start": 0,
               "longest_run_s": 0.2, "breach_start_frame": 0, "breach_start_m": 900.0, "first_breach_m": 900.0,
               "reason": "", "failed_frames": 0, **kw}
    return summary, SequenceFacts.of_summary(summary, [1300.0, 1200.0, None], ["", "", "no_detection"])


PAYLOADS = [
    WorstPayload(WorstPoint(0.9, 12.5, (1.0, -2.0, 300.0)), Nominal(3.0, "", 0.95, ((1.0, 2.0),) * 4)),
    WorstPayload(WorstPoint(None, None, (None, None, None), ((0.5, 0.5),) * 4, 7.5), Nominal(5000.0, "no_detection",
                                                                                          None, None)),
    SequencePayload(SequenceFrames(("a", "b", "c"), (0, 1, 2), (0.0, 0.1, None), (900.0, 800.0, 700.0)),
                    _facts()[1], _facts(roll_deg=0.0, sustained_m=10.0)[1]),
    RiskPayload("guided", 0.01, 1000.0, 0.0, 0.05, 0.95, "stratified", "undecided", 0.01, 0.05, 40,
                {"roll_deg": {"kind": "uniform", "mu": None, "sigma": None}},
                (RiskStratum(0.5, 1, 20, 0.25, 0.25), RiskStratum(0.5, 0, 20, 0.25, 0.25))),
]


@pytest.mark.parametrize("payload", PAYLOADS, ids=lambda p: type(p).__name__)
def test_a_payload_reads_back_what_it_writes(payload):
    row = _row(payload.to_json())
    back = type(payload).of(row)
    assert back == payload and back.to_json() == row.payload
    assert json.dumps(back.to_json()) == json.dumps(row.payload)  # key for key, in the stored order


def test_the_sequence_facts_keep_their_stored_order_with_theta_after_the_frame_count():
    summary, facts = _facts()
    assert list(facts.to_json()) == [*summary, "errors_m", "reasons"] and facts.theta == {"roll_deg": 1.5}


def test_rows_without_a_payload_or_with_another_read_as_none():
    for cls in (WorstPayload, SequencePayload, RiskPayload):
        assert cls.of(_row(None)) is None and cls.of(_row({"errors": {}})) is None
    assert WorstPayload.of(_row(PAYLOADS[2].to_json())) is None and RiskPayload.of(_row(PAYLOADS[0].to_json())) is None


def test_older_rows_read_their_missing_keys_as_none():
    old = WorstPayload.of(_row({"worst": {"conf": 0.5, "error_m": 3.0}}))  # no position, no nominal
    assert old.worst.position is None and old.nominal is None and old.worst.corner_sigma_px is None
    risk = RiskPayload.of(_row({"risk": {**PAYLOADS[3].to_json()["risk"],
                                         "strata": [{"mass": 1.0, "k": 0, "n": 5}]}}))  # before the δ split
    assert risk.strata == (RiskStratum(1.0, 0, 5),) and risk.strata[0].to_json() == {"mass": 1.0, "k": 0, "n": 5}
