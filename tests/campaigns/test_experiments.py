"""Every experiment end to end at tiny scale: real scenes, the oracle pipeline, all methods, store, report."""

import math

import pytest

from vbl_robust.campaigns.pnpcheck import TRUNCATED
from vbl_robust.campaigns.runner import run_campaign
from vbl_robust.paper.experiments import EXPERIMENTS, Options, experiment
from vbl_robust.report.build import build_report
from vbl_robust.specs.campaign import FIGURES as FIGURE_NAMES
from vbl_robust.store.core import ResultStore

TINY = Options(max_evals=8, grid_step_deg=1.0, landscape=(9, 5), time_budgets=(0.02, 0.05), eval_budgets=(4, 8),
               iterations=6)

#: figures each experiment's report must contain
FIGURES = {
    "pnp-validation": {"pnp_solvers"},
    "spatial-1d": {"survival_1d", "landscape_1d"},
    "runtime-1d": {"runtime_1d_time", "runtime_1d_evals", "landscape_1d"},
    "spatial-2d": {"survival_2d", "landscape_2d"},
    "runtime-2d": {"runtime_2d_time", "runtime_2d_evals", "landscape_2d"},
    "distance-profile": {"distance_profile", "landscape_1d"},
    "convergence": {"convergence"},
    "families": {"families_ranking", "families_survival"},
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_experiment_end_to_end(name, tmp_path, small_samples, oracle, full):
    spec = experiment(name).build(0, Options() if full else TINY)
    samples = small_samples[:4] if name == "distance-profile" else small_samples[:2]
    with ResultStore(tmp_path / "results.sqlite") as st:
        summary = run_campaign(spec, samples, st, detector=oracle)
        rows = st.jobs()
    assert summary.status == "finished" and summary.not_measured == 0
    assert summary.done == len(rows) > 0
    main = [r for r in rows if r.role == "main"]
    if name == "pnp-validation":
        for r in rows:
            gt = r.payload["errors"]["ground truth"]
            assert gt["ippe_lm"]["abs_m"] < 1e-6  # exact corners give the pose back (to ≈ 1e-9 m)
            assert set(r.payload["errors"]) == {"ground truth", TRUNCATED, "detector"}
            # LARD's integer labels move the pose (by metres on 1024-px images; far more on these 128-px ones)
            assert r.payload["errors"][TRUNCATED]["ippe_lm"]["abs_m"] > 1e3 * gt["ippe_lm"]["abs_m"]
    else:
        main_methods = {m for b in spec.blocks if b.role == "main" for m in b.methods}
        assert {r.method for r in main} == main_methods
        # a time budget may end before the first evaluation completes (nothing found: no worst error)
        timed = {r.key for r in main if r.budget.max_seconds is not None}
        assert all((r.key in timed and r.nfev == 0 and r.worst_m is None)
                   or (math.isfinite(r.worst_m) and r.nfev >= (0 if r.status == "implied" else 1)) for r in main)
    if name == "convergence":
        po = [t.po_count_before for r in main for t in r.trace]
        assert len(po) == 2 * TINY.iterations and min(po) >= 1
        assert all(r.trace[0].remaining_area == pytest.approx(1.0) for r in main)
    html = build_report(tmp_path).read_text()
    made = {p.stem for p in (tmp_path / "figures").glob("*.png")}
    assert FIGURES[name] <= made, made
    assert html.count("data:image/png;base64,") == len(made)
    assert "<table>" in html and "Provenance" in html and "failed to build" not in html
    if name.startswith("runtime"):  # anytime methods ran once; the report says which results were read off
        assert "read off the run" in html and "Read off a trace: georobust, georobust-av, random" in html
        assert "Run once per budget: apgd" in html


def test_every_experiment_declares_its_figures():
    for name, exp in EXPERIMENTS.items():
        spec = exp.build(0, TINY)
        assert spec.figures and set(spec.figures) <= set(FIGURE_NAMES), name
    assert experiment("spatial-1d").build(0, TINY).figures == ("survival", "landscape")
