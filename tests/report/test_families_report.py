"""The families' ranking, figures and table on synthetic job rows whose answer is known; the sequence audit page."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import pytest

from vbl_robust.analysis.levels import ANY_METHOD, family_profile, rank_families
from vbl_robust.constants import Verdict
from vbl_robust.paper.experiments import family_boxes
from vbl_robust.report import figures as F
from vbl_robust.report.html import figure_png
from vbl_robust.report.sections import family_lines
from vbl_robust.specs.budget import Budget
from vbl_robust.store.rows import JobRow

N = 10
#: family -> method -> the level each of the N images first breaches at (inf: never), chained: breached above it
FIRST_BREACH = {
    "roll_deg": {"georobust": [2] * 6 + [4] * 4, "random": [2] * 6 + [4] * 4},  # < 50 % at L2, < 10 % at L4
    "blur_px": {"georobust": [1] * N, "random": [1] * N},                      # both at L1: most vulnerable
    "haze": {"georobust": [2] * 6 + [math.inf] * 4, "random": [math.inf] * N},  # < 50 % at L2, never < 10 %
    "gamma": {"georobust": [3] * N, "random": [math.inf] * N},                 # GeoRobust alone: L3, L3
    "contrast": {"georobust": [math.inf] * N, "random": [math.inf] * N},       # never
    "noise_std": {"georobust": [math.inf] * N, "random": [5] * 3 + [math.inf] * 7},  # never, lower mean survival
}
EXPECTED = ["blur_px", "roll_deg", "haze", "gamma", "noise_std", "contrast"]


def synthetic_rows() -> list[JobRow]:
    rows = []
    for fam, by_method in FIRST_BREACH.items():
        boxes = family_boxes(fam)
        for method, firsts in by_method.items():
            for i, first in enumerate(firsts):
                for box in boxes:
                    breach = box.level >= first
                    rows.append(JobRow(
                        key=f"{fam}-{method}-{i}-{box.level:g}", experiment="families", kind="search", role="main",
                        method=method, sample_id=f"s{i}", sample_index=i,
                        status="implied" if box.level > first else "done", box=box, budget=Budget(max_evals=10),
                        worst_m=2000.0 if breach else 10.0, verdict=Verdict.BREACH if breach else Verdict.NO_BREACH_FOUND,
                        nfev=0 if box.level > first else 10, chain=f"{fam}-{method}-{i}"))
    return rows


@pytest.fixture(scope="module")
def profile():
    return family_profile(synthetic_rows(), 1000.0)


def test_ranking_order_and_levels_are_the_known_answer(profile):
    assert rank_families(profile) == EXPECTED
    levels = {(p["family"], p["method"]): (p["below_50"], p["below_10"]) for p in profile}
    assert levels[("roll_deg", ANY_METHOD)] == (2.0, 4.0)
    assert levels[("haze", ANY_METHOD)] == (2.0, math.inf)
    assert levels[("gamma", "random")] == (math.inf, math.inf) and levels[("gamma", ANY_METHOD)] == (3.0, 3.0)
    roll = next(p for p in profile if p["family"] == "roll_deg" and p["method"] == "georobust")
    assert roll["survival"] == [100.0, 40.0, 40.0, 0.0, 0.0] and roll["n"] == [N] * 5
    assert roll["labels"][0] == "roll_deg ±2°" and roll["bounds"][-1] == (-30.0, 30.0) and roll["unit"] == "deg"


def test_table_numbers_equal_the_job_rows(profile):
    rows = synthetic_rows()
    lines = family_lines(profile, rank_families(profile))
    assert [ln["family"] for ln in lines][::3] == EXPECTED  # GeoRobust, Random, any method per family
    for ln in lines:
        if ln["method"] == "any method (grid included)":
            continue
        method = "georobust" if ln["method"] == "GeoRobust" else "random"
        for k in range(1, 6):
            at = [r for r in rows if r.method == method and r.box.box.names[0] == ln["family"] and r.box.level == k]
            assert ln[f"L{k}"] == 100.0 * sum(r.worst_m <= 1000.0 for r in at) / len(at)
    by = {(ln["family"], ln["method"]): ln for ln in lines}
    assert by[("roll_deg", "any method (grid included)")]["below_50"] == "L2 (±5°)"
    assert by[("roll_deg", "any method (grid included)")]["below_10"] == "L4 (±20°)"
    assert by[("haze", "GeoRobust")]["below_10"] == "not reached"
    assert by[("blur_px", "Random")]["below_50"] == "L1 ([0, 0.5] px)"
    assert [by[(f, "any method (grid included)")]["rank"] for f in EXPECTED] == list(range(1, 7))


def test_ranking_figure_puts_the_most_vulnerable_on_top(profile, tmp_path):
    order = rank_families(profile)
    fig = F.family_ranking(profile, order)
    ax = fig.axes[0]
    top_down = [t.get_text().split()[0] for t in ax.get_yticklabels()][::-1]
    assert top_down == EXPECTED
    assert "blur_px  (0 to 0.5/1/2/4/8 px)" in [t.get_text() for t in ax.get_yticklabels()]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["L1", "L2", "L3", "L4", "L5", "not\nreached"]
    # markers at the level index: blur_px (top row) at L1 twice; contrast (bottom row) not reached twice
    pts = [tuple(c.get_offsets()[0]) for c in ax.collections if len(c.get_offsets()) == 1]
    top, bottom = len(EXPECTED) - 1, 0
    assert [x for x, y in pts if abs(y - top) < 0.5] == [1.0, 1.0]
    assert [x for x, y in pts if abs(y - bottom) < 0.5] == [6.0, 6.0]
    assert [x for x, y in pts if abs(y - (top - 1)) < 0.5] == [2.0, 4.0]  # roll_deg
    assert [t.get_text() for t in fig.axes[1].get_yticklabels()][::-1][:2] == ["0 %", "0 %"]  # survival at L5
    png = figure_png(fig)
    plt.close(fig)
    (tmp_path / "families_ranking.png").write_bytes(png)
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_survival_figure_has_a_panel_per_family_in_ranking_order(profile):
    fig = F.family_survival(profile, rank_families(profile))
    visible = [a for a in fig.axes if a.get_visible()]
    assert [a.get_title().split("\n")[0] for a in visible] == EXPECTED
    assert visible[1].get_title() == "roll_deg\n±2/5/10/20/30°"
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == ["GeoRobust", "Random", "any method (grid included)"]
    (geo,) = [ln for ln in visible[1].get_lines() if ln.get_label() == "GeoRobust"]
    assert list(geo.get_xdata().round()) == [1, 2, 3, 4, 5] and list(geo.get_ydata()) == [100.0, 40.0, 40.0, 0.0, 0.0]
    assert len(figure_png(fig)) > 5000
    plt.close(fig)
