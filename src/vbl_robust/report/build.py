"""Assemble the HTML report of a run directory from its results store (``vbl-robust report RUN``).

The report is rebuilt from the store alone: every figure is drawn from the stored rows, every figure comes with
the table of the numbers behind it (or a link to it, where another section shows the same rows), and the
provenance of every run (code version, model SHA-256, dataset identity, configuration) closes the page. Figures
are also written as PNG files next to the report, and the run's headline figure (:data:`HEADLINE`) as
``headline.png`` beside it (what an index card of runs shows). The one exception is the pixels of the worst-case gallery: its
images are rebuilt from the run's dataset source (where that is not possible, the gallery says so and shows the
stored facts alone).

Order: the first screen answers "safe where, and how sure" (:mod:`.evidence`: per box one sentence — the verdict,
the images breached, survival with its interval and what it means at this number of images —, the model, data,
date and version, then the table and the survival figure), then the run's settings (the summary), the
worst-case gallery (:mod:`.gallery`), the table per method, box and budget, the declared figures, provenance.
Memory: the gallery is drawn last, after :meth:`.rows.Context.release` drops the rows, and shown in its place:
nothing else the report imports loads torch (``tests/report/test_gallery.py``), so a large store's rows and
torch are never held at once.

Where things are: :mod:`.rows` (the context and which stored rows each section reads), :mod:`.sections` (one
function per section), :mod:`.zone_section` (the vulnerability zones), :mod:`.sequence_section` (a sequence
campaign's errors along the approach), :mod:`.figures` (drawing), :mod:`.html` (the page: long tables sortable,
very long ones folded), :mod:`.evidence` (the first section, and ``evidence.json``), :mod:`.gallery`; this module
only orders the sections and writes the page.

Which figures: the ones the campaign spec declares (``CampaignSpec.figures``, see
:data:`vbl_robust.specs.campaign.FIGURES`; a spec stored without a declaration gets
:func:`~vbl_robust.specs.campaign.default_figures` of its blocks), each drawn by its entry of :data:`SECTIONS`
from the rows it needs; a declared figure without data is left out. The summary always shows the failed
evaluations (``n_failed``) and their counts per failure reason.

Vulnerability zones (:func:`section_zones`, after the landscape) need no declaration: a run with main jobs of a
method that keeps a cover of its box (DIRECT family, grid) gets them. Each such job is replayed on its stored
values (:func:`vbl_robust.campaigns.replay.job_zones`: no evaluation) and classified sound under the run's Lipschitz
constant, else on the method's own estimate (labelled "not sound"); the landscape image's jobs are drawn over its
landscape (:func:`vbl_robust.report.zone_figure.plot_zones`), and a table gives the fractions of Θ per class over all
jobs.
A job whose replay fails is listed as skipped, with the reason.

Budgets read off a trace (the runtime experiments' anytime methods): the main rows are derived per read budget
from the stored runs (:func:`vbl_robust.analysis.readoff.read_off_rows`), and every table that shows them has a
column "read off the run" naming the run they were read from; results of runs of their own leave it empty.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..analysis.readoff import main_rows, reads_trace
from ..atomic import atomic_write
from ..specs.campaign import FIGURES
from ..store.core import ResultStore
from .evidence import SAFETY_FIGURE, Evidence, evidence_of, section_evidence
from .gallery import section_gallery
from .html import esc, page
from .risk_section import section_risk
from .rows import Context, Section, anchor
from .sections import (
    section_best_vs_evals,
    section_convergence,
    section_distance,
    section_families,
    section_landscapes,
    section_methods,
    section_overview,
    section_per_image,
    section_pnp,
    section_provenance,
    section_runtime,
    section_survival_level,
)
from .sequence_section import section_sequences
from .zone_section import section_zones

logger = logging.getLogger(__name__)


#: Titles of the campaigns that are not experiments of the paper.
TITLES = {"audit": "Robustness audit", "risk": "Failure probability under a θ distribution"}

#: The section drawing each figure a campaign can declare (``CampaignSpec.figures``), in report order.
SECTIONS: dict[str, Callable[[Context], Section | None]] = {
    "pnp": section_pnp, "risk": section_risk, "survival": section_survival_level, "runtime": section_runtime, "distance": section_distance,
    "families": section_families, "sequences": section_sequences, "convergence": section_convergence, "landscape": section_landscapes, "progress": section_best_vs_evals,
    "per_image": section_per_image,
}


#: The figure that stands for a paper experiment's run on an index card (``headline.png`` beside the report): the
#: first of these names drawn (a prefix matches, e.g. ``runtime_2d_time``), else the run's first figure. Any other
#: run (an audit, a risk run) stands by its safety figure, survival per box with its intervals
#: (:data:`AUDIT_HEADLINE`), never by a search's convergence.
HEADLINE = ("survival_", "runtime_", "distance_profile", "families_ranking", "sequence_errors", "convergence",
            "pnp_solvers", "risk", SAFETY_FIGURE, "landscape_", "best_vs_evals")
AUDIT_HEADLINE = (SAFETY_FIGURE, "survival_", "risk", "sequence_errors", "landscape_")
#: A truth run (``vbl-robust truth``) stands by its dense grid's landscape, its one figure worth a card.
TRUTH_HEADLINE = ("landscape_", SAFETY_FIGURE)
HEADLINE_FILE = "headline.png"


def _headline(figures: list[Path], out_dir: Path, order: tuple[str, ...] = HEADLINE) -> None:
    """Write the run's headline figure (the first of ``order`` drawn) to ``out_dir/headline.png``; none drawn:
    remove an old one."""
    drawn = [p for p in figures if not p.name.startswith("gallery_")] or figures
    rank = [next((i for i, pre in enumerate(order) if p.stem.startswith(pre)), len(order)) for p in drawn]
    if not drawn:
        (out_dir / HEADLINE_FILE).unlink(missing_ok=True)
        return
    atomic_write(out_dir / HEADLINE_FILE, drawn[rank.index(min(rank))].read_bytes())


def _guarded(name: str, build: Callable[..., Any], *args: Any) -> Any:
    """``build(*args)``, or a section saying it failed (logged): one broken section must not hide the others. An
    operating-system error (a full disk, no permission to write a figure) is not the section's: it ends the report."""
    try:
        return build(*args)
    except OSError:
        raise
    except Exception:
        logger.exception("report section %s failed", name)
        return Section(name, ['<p class="warn">This section failed to build; see the log.</p>'])


def build_report(run: str | Path, out: str | Path | None = None, *, embed: bool = True,
                 titles: Mapping[str, str] | None = None) -> Path:
    """Write ``report.html`` and ``figures/*.png`` for the run directory (or store file) ``run``; returns the HTML
    path. ``out`` defaults to the run directory.

    ``embed`` (the default, ``vbl-robust report``): the page carries every figure (base64), so ``report.html`` alone
    is the whole report — what a user mails, attaches to a ticket or keeps as a CI artefact, where a folder beside
    it gets lost; 1–2 MB with a full worst-case gallery is nothing for one run. ``embed=False`` (a committed
    bundle, :mod:`.bundle`): the page shows ``figures/*.png`` by relative path — a folder that opens offline, a page
    of tens of kB, and a figure that did not change is the same file in git, not another megabyte of base64 in its
    history each time the page is regenerated.

    ``titles``: the titles of the paper's experiments by campaign name, given by what sits above the report (the
    commands and the bundle pass :data:`vbl_robust.paper.experiments.EXPERIMENT_TITLES`; the report cannot import
    the paper). A run named in it is titled so and stands on an index card by :data:`HEADLINE`; any other run
    by :data:`TITLES` (else "Robustness audit") and :data:`AUDIT_HEADLINE`."""
    run = Path(run)
    with ResultStore.open_existing(run, points_on_demand=True) as store:
        spec = store.spec()
        out_dir = Path(out) if out is not None else (run if run.is_dir() else run.parent)
        out_dir.mkdir(parents=True, exist_ok=True)
        ctx = Context(store, spec, out_dir, main_rows(store, spec), store.samples(), embed=embed,
                      main_is_runs=not reads_trace(spec))
        experiment_title = (titles or {}).get(spec.name)
        title = experiment_title if experiment_title is not None else TITLES.get(spec.name, "Robustness audit")
        if spec.name.endswith("-truth"):  # vbl-robust truth RUN: the dense grid behind "no breach found"
            title = f"Dense-grid truth behind {spec.name.removesuffix('-truth')}'s survivors"
        ev = _guarded("evidence", evidence_of, ctx)
        # the first screen answers "safe where, and how sure"; then the run's settings, then the failures
        sections = [_guarded("evidence", section_evidence, ctx, ev) if isinstance(ev, Evidence) else ev,
                    section_overview(ctx, title), section_methods(ctx)]
        declared = spec.report_figures
        for name in FIGURES:
            builds = [SECTIONS[name]] if name in declared else []
            if name == "landscape":  # the zones follow the landscape, declared or not (they need no declaration)
                builds.append(section_zones)
            sections += [_guarded(build.__name__.removeprefix("section_"), build, ctx) for build in builds]
        sections.append(section_provenance(ctx))
        # the gallery shows after the settings but is drawn last, from the evidence alone: its pictures need torch
        # and the images, not the rows, which go first (a large store's rows and torch are not held at once)
        ctx.release()
        sections.insert(2, _guarded("gallery", section_gallery, ctx, ev) if isinstance(ev, Evidence) else None)
        sections = [sec for sec in sections if sec is not None]
    body = [f"<h1>vbl-robust — {esc(title)} <small>({esc(spec.name)})</small></h1>"]
    for sec in sections:  # a section's id is what a link to it names (rows.anchor)
        body.append(f'<section id="{anchor(sec.title)}"><h2>{esc(sec.title)}</h2>')
        body.extend(sec.html)
        body.append("</section>")
    path = out_dir / "report.html"
    atomic_write(path, page(f"vbl-robust {spec.name}", "\n".join(body)))
    _headline(ctx.figures, out_dir, TRUTH_HEADLINE if spec.name.endswith("-truth") else HEADLINE
              if experiment_title is not None else AUDIT_HEADLINE)
    return path
