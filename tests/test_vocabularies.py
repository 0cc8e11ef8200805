"""The vocabularies as enums (issue 58 item 2): each value is the string a store holds, every kind has its
runner or builder, and the line between the pipeline's failures and the tool's is answered by both enums."""

from __future__ import annotations

from vbl_robust.campaigns.work import JOB_RUNNERS
from vbl_robust.consent import CODE_KINDS, DetectorKind
from vbl_robust.constants import FAILURE_REASONS, FailureReason, NotMeasured
from vbl_robust.detect.shipped import BUILDERS, DetectorSpec
from vbl_robust.specs.kinds import JobKind, Role


def test_stored_strings_are_the_values():
    assert [k.value for k in JobKind] == ["search", "pnp", "risk"]
    assert [r.value for r in Role] == ["main", "reference", "landscape"]
    assert JobKind("pnp") is JobKind.PNP and JobKind.PNP == "pnp" and f"{Role.MAIN}" == "main"


def test_every_kind_has_its_runner_and_builder():
    assert set(JOB_RUNNERS) == set(JobKind)
    assert set(BUILDERS) == set(DetectorKind)
    assert set(CODE_KINDS) == {DetectorKind.FACTORY, DetectorKind.PLUGIN}


def test_a_spec_holds_a_member_and_writes_the_value():
    spec = DetectorSpec("oracle")
    assert spec.kind is DetectorKind.ORACLE
    assert type(spec.identity()["kind"]) is str and type(spec.to_dict()["kind"]) is str


def test_failure_reasons_keep_their_meaning_and_the_line():
    assert FAILURE_REASONS == {r.value: r.meaning for r in FailureReason}
    assert FailureReason.PNP_FAILED.meaning == "the PnP solver found no pose"
    assert all(r.flagged and not r.not_measured for r in FailureReason)
    assert all(k.not_measured and not k.flagged for k in NotMeasured)
