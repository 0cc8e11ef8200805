"""The report's first screen (issue 57): per box one sentence — the verdict, the images breached, survival with its
interval and what the interval means at this number of images — then the model (name, short SHA-256, design), the
data kind, the date and the version, all before the first section after the evidence one; counts and rates in
columns of their own; the run's headline figure is its survival per box, not a search's convergence."""

import dataclasses
import json
import re
import sqlite3

import pytest

from vbl_robust.campaigns.audit import audit_spec
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.detect.shipped import DetectorSpec
from vbl_robust.report.build import build_report
from vbl_robust.report.evidence import BoxEvidence, verdict_of, verdict_sentence
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import roll_box
from vbl_robust.specs.settings import PipelineSettings
from vbl_robust.stats import Rate
from vbl_robust.store.core import ResultStore

SOURCE = {"kind": "synthetic", "n": 4, "seed": 5, "width": 128, "height": 128}
MODEL = {"name": "runway-pose v9", "sha256": "ab12cd34ef56" + "0" * 52, "design": "two-stage", "input_size": 640,
         "engine": "onnxruntime", "kind": "file"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """An audit of two boxes where some images breach (ε_safe = 40 m; the oracle's corners off by 1 px), its stored
    detector identity that of a model file."""
    from vbl_robust.scenes.generate import generate

    out = tmp_path_factory.mktemp("first")
    spec = audit_spec(roll_box(5), methods=("random", "georobust"), budget=Budget(max_evals=8))
    block = dataclasses.replace(spec.blocks[0], boxes=(roll_box(5), roll_box(20)))
    spec = dataclasses.replace(spec, blocks=(block,)).with_settings(eps_safe_m=40.0)
    with ResultStore(out / "results.sqlite") as st:
        run_campaign(spec, list(generate(4, seed=5, width=128, height=128)), st,
                     detector=DetectorSpec("oracle", options={"noise_px": 1.0}), dataset_source=SOURCE)
    con = sqlite3.connect(out / "results.sqlite")
    con.execute("UPDATE runs SET detector_json = ?", (json.dumps(MODEL),))
    con.commit()
    con.close()
    return out


@pytest.fixture(scope="module")
def page(run):
    return build_report(run).read_text()


def pct(v: float) -> str:
    """A percent as the sentences round it: whole, one significant digit below 1 %."""
    return f"{v:.0f}" if v >= 1 or v == 0 else f"{v:.1g}"


def first_screen(page: str) -> str:
    """The page up to the first section after the evidence one."""
    start = page.index('<section id="safe-where-and-how-sure">')
    return page[:page.index("<section", start + 1)]


def text(html: str) -> str:
    """What a reader sees of ``html``: tags and soft hyphens dropped, white space collapsed."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", html)).replace("\u00ad", "")


def test_the_first_screen_says_the_verdict_its_interval_and_the_model(run, page):
    ev = json.loads((run / "evidence.json").read_text())
    first = text(first_screen(page))
    assert len(ev["boxes"]) == 2
    for b in ev["boxes"]:
        n, surv = b["images"], b["survivors"]
        lo, hi = Rate(surv, n).ci.low, Rate(surv, n).ci.high
        word = "Not safe" if surv < n else "Not shown safe"
        assert f"{word} on {b['label']}:" in first
        if surv < n:
            assert f"{n - surv} of {n} images breached ({b['misleading']} misleading, {b['flagged']} flagged only)" in first
        assert f"with {n} images it could be anywhere in {pct(lo)}–{pct(hi)} % (95 % interval)" in first
    assert any(b["survivors"] < b["images"] for b in ev["boxes"])  # a breach: the test is not vacuous
    # the model, the data, the date and the version
    assert "runway-pose v9" in first and "sha256 ab12cd34ef56" in first and "two-stage" in first
    assert "synthetic LARD-V2-format approach scenes (not LARD's real images)" in first and "4 synthetic" in first
    assert re.search(r"run \d{4}-\d\d-\d\d \d\d:\d\d UTC", first) and "vbl-robust 0." in first


def test_counts_and_rates_sit_in_columns_of_their_own(page):
    first = first_screen(page)
    table = first[first.index('<table class="headline'):]
    table = table[:table.index("</table>")]
    heads = [text(h).strip() for h in re.findall(r"<th[^>]*>(.*?)</th>", table)]
    assert heads[:5] == ["box", "images", "breached", "misleading", "flagged only"]
    cells = [text(c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", table)]
    assert not [c for c in cells if re.fullmatch(r"\d+ \[.*\]", c)]  # never "3 [6.7, 65.2]"
    # every table scrolls inside the page rather than running off it at 800 px
    assert first.count('<div class="tw"><table') == first.count("<table")


def test_an_audits_headline_figure_is_its_survival_per_box(run, page):
    assert (run / "headline.png").read_bytes() == (run / "figures" / "safety_per_box.png").read_bytes()


def test_a_store_without_a_design_says_so(run, tmp_path):
    old = tmp_path / "old"
    old.mkdir()
    src, dst = sqlite3.connect(run / "results.sqlite"), sqlite3.connect(old / "results.sqlite")
    src.backup(dst)
    src.close()
    dst.execute("UPDATE runs SET detector_json = ?", (json.dumps({k: v for k, v in MODEL.items() if k != "design"}),))
    dst.commit()
    dst.close()
    first = text(first_screen(build_report(old).read_text()))
    assert "runway-pose v9 (design not recorded, input 640 px" in first


def box(survivors, n=10, certified=0, misleading=2):
    ci = Rate(survivors, n).ci
    return BoxEvidence(label="±15°", ranges={}, methods=("random",), images=n, evaluations=100, survivors=survivors,
                       misleading=misleading, flagged=n - survivors - misleading, survival_ci=(ci.low, ci.high),
                       misleading_ci=None, residual_bound=None, remaining_area_pct=None, search_status={},
                       certified=certified)


@pytest.mark.parametrize(("b", "verdict", "says"), [
    (box(7), "not-safe", "Not safe</b> on <b>±15°</b>: 3 of 10 images breached (2 misleading, 1 flagged only); "
                         "survival 70 %, and with 10 images it could be anywhere in 35–93 % (95 % interval)."),
    (box(10, misleading=0), "not-shown", "no breach found on the 10 images, which proves nothing by itself"),
    (box(10, certified=10, misleading=0), "safe", "every one of the 10 images certified"),
    (box(0, n=0, misleading=0), "none", "no image measured (survival –)"),
])
def test_one_sentence_per_box(b, verdict, says):
    assert verdict_of(b) == verdict
    assert says in verdict_sentence(b, "image")


def test_a_truth_run_stands_by_its_dense_grids(tmp_path):
    """A run of dense grids alone (``vbl-robust truth``) has a first screen too: the grid is its search; its card's
    figure stays the landscape."""
    from vbl_robust.scenes.generate import generate
    from vbl_robust.specs.campaign import Block, CampaignSpec

    blk = Block(boxes=(roll_box(20),), methods=("grid",), budgets=(Budget(max_evals=9),), role="reference")
    spec = CampaignSpec("spatial-1d-truth", (blk,), figures=("landscape",), settings=PipelineSettings(eps_safe_m=40.0))
    with ResultStore(tmp_path / "results.sqlite") as st:
        run_campaign(spec, list(generate(3, seed=5, width=128, height=128)), st,
                     detector=DetectorSpec("oracle", options={"noise_px": 1.0}), dataset_source=SOURCE)
    first = text(first_screen(build_report(tmp_path).read_text()))
    assert re.search(r"(Not safe|Not shown safe) on ±20°: .*with 3 images it could be anywhere in", first)
    assert (tmp_path / "headline.png").read_bytes() == (tmp_path / "figures" / "landscape_1d.png").read_bytes()
