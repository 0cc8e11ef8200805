import dataclasses
import math

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from vbl_robust.analysis.levels import DistanceLine
from vbl_robust.analysis.metrics import ConvergenceLine, PnpLine
from vbl_robust.analysis.summary import Summary
from vbl_robust.report import figures as F
from vbl_robust.report.figure_style import REFERENCE, style
from vbl_robust.report.view_figure import worst_view
from vbl_robust.report.zone_figure import COLOURS, zones_figure


def summary_rows():
    out = []
    for m, base in (("georobust", 20.0), ("random", 50.0), ("apgd", 70.0), (REFERENCE, 10.0)):
        for lv in (2.0, 5.0, 10.0):
            out.append(Summary(
                method=m, box_level=lv, box_label=f"±{lv:g}°", budget_label=None, survival=20.0 * round(base / lv / 10),
                survivors=round(base / lv / 10), n=5, flagged=0, misleading=5 - round(base / lv / 10), residual=None,
                max_seconds=lv / 10, max_evals=float(lv * 10), max_iters=math.nan, median_worst_m=100.0 * lv,
                n_empty=0, mean_worst_m=100.0 * lv, breaches=0, certified=0, not_measured=0, nfev=50, mean_nfev=10.0,
                failed_evals=None, failures={}, median_search_s=0.1, read_from=""))
    return out


def labels(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_survival_vs_level_has_one_line_per_method_and_the_reference():
    fig = F.survival_vs_level(summary_rows(), title="t", xlabel="roll budget")
    ax = fig.axes[0]
    assert isinstance(fig, Figure)
    assert labels(ax)[:4] == ["GeoRobust", "Random", "APGD", "grid (true worst case)"]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["±2°", "±5°", "±10°"]
    assert ax.get_ylim() == (-3, 103)


def test_runtime_has_survival_and_median_panels_with_eps():
    fig = F.runtime(summary_rows(), axis="max_seconds", title="t", eps_safe_m=1000.0,
                    reference={"survival": 5.0, "median_worst_m": 3000.0})
    a1, a2 = fig.axes[:2]
    assert a1.get_xscale() == "log" and a2.get_yscale() == "log"
    assert any(line.get_ydata()[0] == 1000.0 for line in a2.get_lines())  # ε_safe line
    assert "ε_safe = 1000 m" in [t.get_text() for t in fig.legends[0].get_texts()]


def test_distance_profile_marks_no_phi_crit_at_the_limit():
    prof = [DistanceLine(q, 1000.0 * q, 1000.0 * (q + 1), "georobust", 3, v, 1, [50.0, 5.0, 0.0], v)
            for q, v in ((1, 10.0), (2, math.inf))]
    fig = F.distance_profile(prof, limit_deg=45.0, budgets=[5, 10, 45])
    assert [t.get_text() for t in fig.axes[0].texts] == ["10°"]
    bars = [p for p in fig.axes[0].patches if p.get_width() < 1]
    assert bars[0].get_height() == 10.0 and bars[1].get_height() > 45.0 and bars[1].get_hatch() == "//"
    assert fig.axes[1].get_ylabel() == "survival rate S_rate (%)"


def _conv(iterations, n):
    """Convergence lines: mean = median 10/k, quartiles and deciles around it, a 500 outlier as maximum."""
    def spread(k):
        return [10.0 / k, 1.0, 8.0 / k, 9.0 / k, 10.0 / k, 11.0 / k, 12.0 / k, 500.0]

    return [ConvergenceLine(k, n, *spread(k), *spread(k), 10.0 / k, 2.0 * k, 100.0) for k in range(1, iterations + 1)]


def test_convergence_and_landscapes_and_pnp():
    fig = F.convergence(_conv(5, 3))
    assert len(fig.axes) == 2 and fig.axes[0].get_yscale() == "log"  # outliers: |PO_k| on a log axis
    r, c = np.meshgrid(np.linspace(-10, 10, 9), np.linspace(0.7, 1.4, 5), indexing="ij")
    xs = np.stack([r.ravel(), c.ravel()], axis=1)
    fs = 10.0 + 300.0 * np.abs(xs[:, 0])
    fig = F.landscape_2d(xs, fs, ["roll_deg", "contrast"], {"random": xs[:4]}, eps_safe_m=1000.0, title="t",
                         worst={"random": xs[3]})
    assert fig.axes[0].get_xlabel() == "roll φ (°)"
    assert "Random (4 points)" in [t.get_text() for t in fig.legends[0].get_texts()]
    fig = F.landscape_1d(xs[:9, :1], fs[:9], "roll_deg", {"apgd": (xs[:3, :1], fs[:3])}, eps_safe_m=1000.0, title="t")
    assert "APGD (3 points)" in labels(fig.axes[0])
    pnp = [PnpLine(s, v, 4, 0, 30.0, 60.0, 1.0, 2.0, 3.0) for s in ("ground truth", "detector")
           for v in ("ippe_lm", "iterative")]
    fig = F.pnp_comparison(pnp)
    assert [a.get_title() for a in fig.axes] == ["ground truth keypoints", "detector keypoints"]
    assert fig.axes[0].get_xticklabels()[0].get_text() == "ippe_lm\n0/4 failed"


@pytest.mark.parametrize("method", ["georobust", "unknown-method"])
def test_style_has_defaults(method):
    assert {"color", "marker", "label", "linestyle"} <= set(style(method))


def outside(fig):
    """How far (inches; 0 when nothing) the drawn texts and axes of ``fig`` — titles, labels, tick labels, legends —
    reach beyond its edges, where the PNG clips them: (left, bottom, right, top)."""
    fig.canvas.draw()
    bb = fig.get_tightbbox(fig.canvas.get_renderer())
    w, h = fig.get_size_inches()
    return tuple(round(max(0.0, v), 2) for v in (-bb.x0, -bb.y0, bb.x1 - w, bb.y1 - h))


def every_figure():
    """One figure of each kind the report draws, with labels as long as a report's."""
    rows = [dataclasses.replace(r, n=100) for r in summary_rows()]
    long_ticks = {2.0: "±2°, c∈[0.9, 1.1]", 5.0: "±15°, c∈[0.6, 1.6]", 10.0: "±30°, c∈[0.4, 2.5]"}
    yield "survival", F.survival_vs_level(rows, title="Survival vs roll and contrast budget", tick_labels=long_ticks,
                                          xlabel="perturbation box (roll half-width, contrast range)")
    yield "runtime", F.runtime(rows, axis="max_seconds", eps_safe_m=1000.0, reference={"survival": 5.0,
                               "median_worst_m": 3000.0}, title="Time budget per image, box ±10°, c∈[0.7, 1.4]")
    prof = [DistanceLine(q, 1000.0 * q, 1000.0 * (q + 1), m, 25, 10.0 * q, 20, [50.0, 5.0, 0.0], 10.0 * q)
            for q in (1, 2, 3, 4) for m in ("georobust", "apgd")]
    yield "distance", F.distance_profile(prof, limit_deg=45.0, budgets=[5, 10, 45])
    curves = {m: (np.arange(1, 201), np.linspace(100, 900, 200)) for m in ("georobust", "random", "apgd")}
    yield "progress", F.best_vs_evals(curves, eps_safe_m=1000.0, title="Search progress (median over images)")
    r, c = np.meshgrid(np.linspace(-30, 30, 9), np.linspace(0.4, 2.5, 5), indexing="ij")
    xs = np.stack([r.ravel(), c.ravel()], axis=1)
    fs = 10.0 + 300.0 * np.abs(xs[:, 0])
    yield "landscape", F.landscape_2d(xs, fs, ["roll_deg", "contrast"], {"random": xs[:4]}, eps_safe_m=1000.0,
                                      worst={"random": xs[3]},
                                      title="L over ±30°, c∈[0.4, 2.5], image synth_s0_000000 (slant distance 5597 m)")
    yield "convergence", F.convergence(_conv(29, 100), title="GeoRobust convergence")
    pnp = [PnpLine(s, v, 1000, 12, 30.0, 60.0, 1.0, 2.0, 3.0) for s in ("ground truth", "detector")
           for v in ("ippe_lm", "iterative", "sqpnp", "ippe")]
    yield "pnp", F.pnp_comparison(pnp)
    yield "risk", F.risk_per_image({"mc": [(i, 0.01, 0.0, 0.05) for i in range(40)]}, 40, 0.01)
    img = np.full((64, 80, 3), 0.5)
    corners = np.array([[50.0, 30.0], [40.0, 30.0], [35.0, 50.0], [55.0, 50.0]])
    yield "gallery", worst_view(img, img, corners, corners + 3, corners + 6, predicted_before=corners + 0.5,
                                  confident=False, titles=("unperturbed: L(0) = 812 m", "perturbed at θ*: L = 5000 m"))
    # a grid stopped at its first breach: part of the box evaluated, no method's worst point drawn
    yield "landscape_partial", F.landscape_2d(
        xs[np.abs(xs[:, 0]) <= 15], fs[np.abs(xs[:, 0]) <= 15], ["roll_deg", "contrast"], {}, eps_safe_m=1000.0,
        bounds=[(-30.0, 30.0), (0.4, 2.5)], title="L over ±30°, c∈[0.4, 2.5], image synth_s0_000047 (slant distance "
        "2469 m); the grid stopped at its first breach after 25 of 1681 points (blank: not evaluated)")
    yield "zones", zones_figure(zone_map_2d(), landscape=(xs, fs),
                                  title="GeoRobust zones on ±30°, c∈[0.4, 2.5], image synth_s0_000047 — estimate K̂: "
                                        "not sound (the search's own Lipschitz estimate)")
    yield "safety", F.survival_per_box(boxes_evidence(), eps_safe_m=1000.0)


def zone_map_2d():
    """The zones of a GeoRobust run over a 2-D box with a breach on its right."""
    from vbl_robust.search.api import make_optimizer
    from vbl_robust.search.zones import zones
    from vbl_robust.space import ParameterBox

    box = ParameterBox({"roll_deg": (-30.0, 30.0), "contrast": (0.4, 2.5)})
    opt = make_optimizer("georobust", box, max_evals=60)
    while len(x := opt.ask()):
        opt.tell(x, np.where(x[:, 0] > 12.0, 5000.0, 20.0 + 30.0 * np.abs(x[:, 0])))
    return zones(opt.cells(), 1000.0, estimate=True)


def boxes_evidence():
    """Six boxes of a spatial-2d run (labels as long as a report's), survival falling."""
    from vbl_robust.report.evidence import BoxEvidence
    from vbl_robust.stats import Rate

    out = []
    for lab, surv, mis in (("±2°, c∈[0.9, 1.1]", 82, 18), ("±5°, c∈[0.8, 1.25]", 75, 25), ("±10°, c∈[0.7, 1.4]", 66, 34),
                           ("±15°, c∈[0.6, 1.6]", 64, 36), ("±20°, c∈[0.5, 2]", 56, 43), ("±30°, c∈[0.4, 2.5]", 25, 65)):
        ci = Rate(surv, 100).ci
        out.append(BoxEvidence(label=lab, ranges={}, methods=("random",), images=100, evaluations=1, survivors=surv,
                               misleading=mis, flagged=100 - surv - mis, survival_ci=(ci.low, ci.high),
                               misleading_ci=None, residual_bound=None, remaining_area_pct=None, search_status={}))
    return out


#: The widest a report shows a figure (CSS px): the page's 1100 px less its padding (a laptop's 1280 px window).
PAGE_PX = 1068


def smallest_text_px(fig, dpi=110):
    """The smallest font of the drawn texts of ``fig`` (CSS px) when its PNG (at ``dpi``) is shown at most
    :data:`PAGE_PX` wide."""
    from matplotlib.text import Text

    fig.canvas.draw()
    scale = min(1.0, PAGE_PX / (fig.get_figwidth() * dpi)) * dpi / 72
    sizes = [t.get_fontsize() for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]
    return min(sizes) * scale


@pytest.fixture(scope="module")
def drawn():
    return dict(every_figure())


NAMES = ["survival", "runtime", "distance", "progress", "landscape", "convergence", "pnp", "risk", "gallery",
         "landscape_partial", "zones", "safety"]


@pytest.mark.parametrize("name", NAMES)
def test_no_title_label_or_legend_is_clipped(name, drawn):
    assert outside(drawn[name]) == (0, 0, 0, 0)


@pytest.mark.parametrize("name", NAMES)
def test_every_text_is_readable_at_a_laptops_width(name, drawn):
    assert smallest_text_px(drawn[name]) >= 9.0


@pytest.mark.parametrize("name", NAMES)
def test_axes_name_parameters_by_their_display_names(name, drawn):
    """One table of display names ("roll φ (°)"), never a parameter's code name ("roll_deg (deg)")."""
    import re

    from vbl_robust.perturb.registry import PERTURBATIONS

    raw = re.compile(r"\b(" + "|".join(n for n in PERTURBATIONS if "_" in n) + r")\b")
    labels = [t for ax in drawn[name].axes for t in (ax.get_xlabel(), ax.get_ylabel(), ax.get_title())]
    assert not [t for t in labels if raw.search(t)]


def _marker_paths(ax):
    """The marker paths of what is drawn in ``ax`` with data (scatter collections and marker lines)."""
    drawn = []
    for c in ax.collections:
        if len(c.get_offsets()) and c.get_paths():
            drawn.append(c.get_paths()[0].vertices.round(6).tobytes())
    for line in ax.get_lines():
        if len(line.get_xdata()) and line.get_marker() not in (None, "", "None", "none"):
            drawn.append(line.get_marker())
    return drawn


@pytest.mark.parametrize("name", NAMES)
def test_a_legend_names_only_markers_that_are_drawn(name, drawn):
    """An empty proxy in a legend (``scatter([], [])``) stands for something drawn: the same marker with data."""
    fig = drawn[name]
    fig.canvas.draw()
    for ax in fig.axes:
        present = _marker_paths(ax)
        for c in ax.collections:
            if not len(c.get_offsets()) and c.get_label() and not c.get_label().startswith("_"):
                assert c.get_paths()[0].vertices.round(6).tobytes() in present, c.get_label()


def test_a_landscapes_axes_span_the_box_its_title_names(drawn):
    ax = drawn["landscape_partial"].axes[0]
    assert ax.get_xlim() == (-30.0, 30.0) and ax.get_ylim() == (0.4, 2.5)
    assert "stopped at its first breach" in ax.get_title()
    texts = [t.get_text() for t in drawn["landscape_partial"].legends[0].get_texts()]
    assert "worst point found" not in texts  # no star drawn, none named
    assert "worst point found" in [t.get_text() for t in drawn["landscape"].legends[0].get_texts()]


def test_the_zones_ruled_out_colour_stands_out_from_its_landscape(drawn):
    """The "ruled out" green is not a colour of the landscape's colour map (viridis' greens swallowed it)."""
    from matplotlib.colors import to_rgb

    from vbl_robust.report.zone_figure import LANDSCAPE_CMAP
    from vbl_robust.search.zones import RULED_OUT

    cmap = plt.get_cmap(LANDSCAPE_CMAP)(np.linspace(0, 1, 256))[:, :3]
    green = np.array(to_rgb(COLOURS[RULED_OUT]))
    assert np.min(np.linalg.norm(cmap - green, axis=1)) > 0.3
    ax = drawn["zones"].axes[0]
    assert ax.get_xlabel() == "roll φ (°)" and ax.get_ylabel() == "contrast factor α"


def test_the_gallery_draws_pixels_as_blocks_with_predictions_on_both_sides(drawn):
    fig = drawn["gallery"]
    left, right = fig.axes[:2]
    assert [im.get_interpolation() for ax in (left, right) for im in ax.get_images()] == ["nearest", "nearest"]
    assert left.get_xlabel().startswith("corner shift: TR 0.7, TL 0.7")  # the unperturbed prediction, 0.5 px off
    assert right.get_xlabel().startswith("corner shift: TR 4.2")
    x0, x1 = left.get_xlim()
    assert x1 - x0 <= 40  # scaled to the runway (a 20 px quadrilateral), not a 128 px crop


def test_the_progress_median_never_falls_when_searches_start_late():
    """A median over the images that happen to have a point at a count fell (late starters joined low); every
    image counts at every count."""
    from vbl_robust.report.sections import progress_curves
    from vbl_robust.search.result import TraceRow
    from vbl_robust.store.rows import JobRow

    def row(sid, nfev, best):
        trace = tuple(TraceRow(iteration=i, nfev=n, elapsed=0.0, best_value=b, best_x=None, batch_size=1, n_failed=0)
                      for i, (n, b) in enumerate(zip(nfev, best, strict=True)))
        return JobRow(key=sid, experiment="t", kind="search", role="main", method="georobust", sample_id=sid,
                      sample_index=0, status="done", trace=trace)

    rows = [row("a", [1, 5, 9], [1250.0, 1300.0, 1400.0]), row("b", [1, 9], [1200.0, 1200.0]),
            row("c", [5, 9], [300.0, 700.0]), row("d", [5], [200.0])]  # d stopped early: keeps its value
    n, med = progress_curves(rows)["georobust"]
    assert n[0] == 5 and np.all(np.diff(med) >= 0)
    assert med[0] == pytest.approx(np.median([1300.0, 1200.0, 300.0, 200.0]))
    assert med[-1] == pytest.approx(np.median([1400.0, 1200.0, 700.0, 200.0]))
