import dataclasses
import re

import pytest

from vbl_robust.campaigns.audit import audit_spec
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.report.build import build_report
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import Block, CampaignSpec, roll_box, roll_contrast_box
from vbl_robust.store.core import ResultStore
from vbl_robust.store.rows import RunProvenance


@pytest.fixture(scope="module")
def samples():
    from vbl_robust.scenes.generate import generate

    return generate(3, seed=5, width=128, height=128)


def test_audit_report_is_self_contained_with_figures_tables_and_provenance(tmp_path, samples):
    spec = audit_spec(roll_contrast_box(10, (0.7, 1.4)), methods=("georobust", "random"), budget=Budget(max_evals=10),
                      landscape=(7, 5))
    det = DetectorSpec("oracle", options={"noise_px": 0.5})
    with ResultStore(tmp_path / "results.sqlite") as st:
        run_campaign(spec, samples, st, detector=det, dataset_source={"kind": "synthetic", "n": 3})
    html = build_report(tmp_path).read_text()
    assert not re.search(r'src="(?!data:)', html)  # nothing external
    for needle in ("Per image: worst case found", "Loss landscape", "Worst error found vs evaluations", "Provenance",
                   "oracle detector returns the exact", "GeoRobust worst (m)", "synth"):
        assert needle in html, needle
    assert {p.name for p in (tmp_path / "figures").glob("*.png")} >= {"landscape_2d.png", "best_vs_evals.png"}
    # rebuilding into another directory works from the store alone
    other = build_report(tmp_path / "results.sqlite", tmp_path / "copy")
    assert other.parent == tmp_path / "copy" and (tmp_path / "copy" / "figures" / "landscape_2d.png").exists()


def test_report_warns_about_incomplete_runs_and_jobs_not_measured(tmp_path, samples):
    """An image lost during the run is not measured: a banner on the first screen names it, the table lists it,
    and no number counts it (the box's survival is the other image's alone; evidence.json lists it apart)."""
    import json

    spec = CampaignSpec("audit", (Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=4),)),))
    missing = dataclasses.replace(samples[0], id="gone", image_path=tmp_path / "gone.png", _image=None, _loader=None)
    with ResultStore(tmp_path / "results.sqlite") as st:
        run_campaign(spec, [missing, samples[1]], st, detector=DetectorSpec("oracle"), precheck=False)
        rid = st.begin_run(RunProvenance(jobs_total=9, jobs_skipped=1))
        st.end_run(rid, "interrupted", 0, 1.0)
    html = build_report(tmp_path).read_text()
    first = html[: html.index('<section id="summary">')]  # the first screen, before the run's settings
    assert "1 of 2 jobs not measured" in first and "input unavailable: gone: image file not found" in first
    assert "could not be measured by the tool" in html and str(tmp_path) not in html
    assert "campaign is incomplete (2 of 9 jobs)" in html
    ev = json.loads((tmp_path / "evidence.json").read_text())
    (box,) = ev["boxes"]
    assert box["images"] == 1 and box["survivors"] == 1  # the measured image alone
    assert ev["not_measured"] == [{"sample_id": "gone", "method": "random", "box": box["label"],
                                   "kind": "input unavailable", "reason": "gone: image file not found"}]


def test_report_errors_name_the_run(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results store"):
        build_report(tmp_path)
    ResultStore(tmp_path / "results.sqlite").close()
    with pytest.raises(ValueError, match="holds no campaign"):
        build_report(tmp_path)


def test_sections_cover_every_declarable_figure_in_order():
    from vbl_robust.report.build import SECTIONS
    from vbl_robust.specs.campaign import FIGURES

    assert tuple(SECTIONS) == FIGURES


def test_figures_come_from_the_spec_not_from_the_experiment_name(tmp_path, samples):
    blk = Block(boxes=(roll_box(2), roll_box(5)), methods=("random",), budgets=(Budget(max_evals=4),))
    for name, figures, made, absent in (
        ("a-new-experiment", ("survival",), {"survival_1d"}, "Per image: worst case found"),
        ("audit", ("per_image",), set(), "Survival vs roll budget"),  # the name "audit" draws nothing by itself
    ):
        out = tmp_path / name
        with ResultStore(out / "results.sqlite") as st:
            run_campaign(CampaignSpec(name, (blk,), figures=figures), samples[:2], st, detector=DetectorSpec("oracle"))
        html = build_report(out).read_text()
        # the declared figures, and the first screen's survival per box (every run with a box has it)
        assert {p.stem for p in (out / "figures").glob("*.png")} == made | {"safety_per_box"}
        assert absent not in html and "best_vs_evals" not in html
    assert "Per image: worst case found" in html
    with pytest.raises(ValueError, match="unknown figure"):
        CampaignSpec("x", (blk,), figures=("heatmap",))


def test_report_shows_failed_evaluations_per_reason(tmp_path):
    from vbl_robust.constants import FAILURE_REASONS
    from vbl_robust.store.rows import JobRow

    spec = CampaignSpec("audit", (Block(boxes=(roll_box(5),), methods=("random",), budgets=(Budget(max_evals=10),)),))
    with ResultStore(tmp_path / "results.sqlite") as st:
        st.bind_campaign(spec.name, spec.to_dict(), {"kind": "oracle", "sha256": None, "name": "oracle"})
        st.commit([JobRow(key=f"k{i}", experiment="audit", kind="search", role="main", method="random",
                          sample_id=f"s{i}", sample_index=i, status="done", box=roll_box(5), budget=Budget(max_evals=10),
                          worst_m=5000.0, verdict="breach", nfev=10, n_failed=n, failures=f, worst_reason="no_detection")
                   for i, (n, f) in enumerate([(3, {"no_detection": 2, "pnp_failed": 1}), (1, {"no_detection": 1})])])
    html = build_report(tmp_path).read_text()
    assert "failed evals" in html and "Failed evaluations by reason" in html
    assert FAILURE_REASONS["no_detection"] in html and FAILURE_REASONS["pnp_failed"] in html
    assert re.search(r"<td[^>]*>20</td><td[^>]*>4</td><td[^>]*>3</td><td[^>]*>1</td>", html)  # evals, failed, per reason


def test_searches_with_no_evaluation_in_time_are_counted_apart_in_the_report_and_the_cli(tmp_path, capsys):
    """A time-budgeted search that completed no evaluation survives (it found nothing), but the tables must say so
    rather than show a bare 100 % survival with no worst error."""
    from types import SimpleNamespace

    from vbl_robust.cli.run import finish
    from vbl_robust.store.rows import JobRow

    budget = Budget(max_seconds=0.1, stop_at_breach=False)
    spec = CampaignSpec("audit", (Block(boxes=(roll_box(5),), methods=("apgd", "random"), budgets=(budget,)),))
    rows = [("apgd", None, 0, "no breach found"), ("random", 1200.0, 3, "breach")]
    with ResultStore(tmp_path / "results.sqlite") as st:
        st.bind_campaign(spec.name, spec.to_dict(), {"kind": "oracle", "sha256": None, "name": "oracle"})
        st.commit([JobRow(key=f"k{i}", experiment="audit", kind="search", role="main", method=m, sample_id="s0",
                          sample_index=0, status="done", box=roll_box(5), budget=budget, worst_m=w, verdict=v,
                          nfev=n) for i, (m, w, n, v) in enumerate(rows)])
    html = build_report(tmp_path).read_text()
    assert "no evaluation in time" in html
    done = SimpleNamespace(done=2, skipped=0, not_measured=0, seconds=1.0, status="finished")
    assert finish(tmp_path, done, csv=None, parquet=None, report=False)
    out = capsys.readouterr().out
    assert "no eval in time" in out and "count as survivors" in out
    apgd = next(line for line in out.splitlines() if "apgd" in line)
    # survival with its interval, 1 empty search, no median worst
    assert re.search(r"100\.0 \[2\.5, 100\.0\]\s*│\s*1\s*│\s*–", apgd), apgd
    random = next(line for line in out.splitlines() if "random" in line)
    assert re.search(r"0\.0 \[0\.0, 97\.5\]\s*│\s*0\s*│\s*1200\.0", random), random


def test_markdown_survival_has_a_column_per_budget_when_the_run_has_several(tmp_path):
    """A runtime experiment's survival is per budget: pooling the budgets into one cell would mean nothing."""
    from vbl_robust.report.markdown import survival_markdown
    from vbl_robust.store.rows import JobRow

    short, long = Budget(max_seconds=0.5, stop_at_breach=False), Budget(max_evals=10, stop_at_breach=False)
    spec = CampaignSpec("runtime", (Block(boxes=(roll_box(5),), methods=("apgd", "random"), budgets=(long, short)),))
    worst = {("apgd", "s0", long): 1500.0, ("apgd", "s1", long): 300.0, ("random", "s0", long): 200.0,
             ("random", "s1", long): 1200.0, ("apgd", "s0", short): None, ("apgd", "s1", short): 100.0,
             ("random", "s0", short): 200.0, ("random", "s1", short): 400.0}
    with ResultStore(tmp_path / "results.sqlite") as st:
        st.bind_campaign(spec.name, spec.to_dict(), {"kind": "oracle", "sha256": None, "name": "oracle"})
        st.commit([JobRow(key=f"k{i}", experiment="runtime", kind="search", role="main", method=m, sample_id=s,
                          sample_index=int(s[1]), status="done", box=roll_box(5), budget=b,
                          worst_m=w, verdict="no breach found" if w is None or w <= 1000 else "breach",
                          nfev=0 if w is None else 10) for i, ((m, s, b), w) in enumerate(worst.items())])
    text = survival_markdown(tmp_path)
    head, rule, *body = [ln for ln in text.splitlines() if ln.startswith("|")][:5]
    assert [c.strip() for c in head.strip("|").split("|")] == ["method", short.label, long.label]  # time budgets first
    cells = {r[0]: r[1:] for r in ([c.strip() for c in ln.strip("|").split("|")] for ln in body)}
    # each cell: survival % [exact 95 % interval of 2 images] (breaches)
    assert cells["apgd"] == ["100.0 [15.8, 100.0] (0)", "50.0 [1.3, 98.7] (1)"] and cells["random"] == cells["apgd"]
    assert cells["any of them"] == ["100.0 [15.8, 100.0] (0)", "0.0 [0.0, 84.2] (2)"]
    # the breaches' kinds: no points stored here, so a breach whose worst is silent is misleading
    kinds = text.split("Breaches by kind")[1]
    assert "| apgd | 0 / 0 | 1 / 0 |" in kinds and "| any of them | 0 / 0 | 2 / 0 |" in kinds
    assert "Evaluations spent per job" not in text
