"""The report's context and row selection: which stored rows each section reads (main, reference, landscape)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.reference import reference_rows
from ..atomic import atomic_write
from ..specs.campaign import BoxSpec, CampaignSpec
from ..specs.kinds import JobStatus
from ..store.core import ResultStore
from ..store.payloads import Nominal, WorstPayload
from ..store.rows import JobRow, SampleRecord
from .figure_style import method_order
from .html import figure_png, img, img_file


@dataclass
class Section:
    title: str
    html: list[str] = field(default_factory=list)


@dataclass
class Context:
    """What every section builder needs: the stored rows, the spec and where figures go (``figures/`` under
    ``out_dir``); ``embed``: the page carries each figure itself, else it shows the file (``build_report``'s
    ``embed``)."""

    store: ResultStore
    spec: CampaignSpec
    out_dir: Path
    main: list[JobRow]
    samples: dict[str, SampleRecord]
    figures: list[Path] = field(default_factory=list)
    embed: bool = True
    #: ``main`` is every stored main search row the tool measured, none read off a trace (:func:`~vbl_robust.
    #: analysis.readoff.main_rows` of a spec that reads no trace): :attr:`runs` is ``main`` itself, not a second
    #: copy of every row.
    main_is_runs: bool = False

    @property
    def eps(self) -> float:
        return self.spec.settings.eps_safe_m

    @cached_property
    def risk(self) -> list[JobRow]:
        """The stored failure-probability jobs (``vbl-robust risk``) the tool measured, with their points (every
        draw)."""
        return [r for r in self.store.jobs(kind="risk", with_points=True, with_trace=False) if r.measured]

    @cached_property
    def runs(self) -> list[JobRow]:
        """The stored main search jobs the tool measured, with their points (as run: no rows read off a trace)."""
        if self.main_is_runs:
            return self.main
        return [r for r in self.store.jobs(kind="search", role="main", with_points=True, with_trace=False)
                if r.measured]

    @cached_property
    def nominal(self) -> dict[str, Nominal]:
        """Per sample, its unperturbed facts as its main jobs store them (:class:`~vbl_robust.store.
        payloads.Nominal`: L(0), reason, confidence, predicted corners); a sample missing: its jobs were stored
        before they held it."""
        return {r.sample_id: p.nominal for r in self.main if (p := WorstPayload.of(r)) is not None and p.nominal}

    @cached_property
    def unmeasured(self) -> list[JobRow]:
        """Every stored job the tool could not measure (any kind and role): in no rate, listed apart."""
        return self.store.jobs(with_trace=False, measured=False)

    def release(self) -> None:
        """Drop every row read (``main`` and the rows read on first use: :attr:`runs`, :attr:`risk`,
        :attr:`unmeasured`, :attr:`nominal`) and the store's cache of points: what is built after this needs none
        of them (the worst-case gallery, whose pictures need torch: a large store's rows do not sit beside it)."""
        self.main = []
        for name in ("runs", "risk", "unmeasured", "nominal"):
            self.__dict__.pop(name, None)
        self.store.forget_points()

    def figure(self, fig: Any, name: str, caption: str, *, colors: int | None = None) -> str:
        """``fig`` written to ``figures/<name>.png`` (atomically; ``colors``: a palette of that many colours, see
        :func:`~vbl_robust.report.html.figure_png`) and closed; returns its ``<figure>`` HTML (:meth:`show`)."""
        png = figure_png(fig, colors=colors)
        plt.close(fig)
        path = self.out_dir / "figures" / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, png)
        return self.figure_file(path, name, caption, png)

    def figure_file(self, path: Path, name: str, caption: str, png: bytes | None = None) -> str:
        """A PNG already written under ``figures/`` (e.g. by :func:`vbl_robust.report.zone_figure.plot_zones`; ``png``:
        its bytes when at hand): embedded, or with ``embed`` off shown from its file, relative to the page."""
        self.figures.append(path)
        if self.embed:
            return img(path.read_bytes() if png is None else png, name, caption)
        return img_file(path.relative_to(self.out_dir).as_posix(), name, caption)


def anchor(title: str) -> str:
    """The id of a section's heading (``"Per method, box and budget"`` → ``"per-method-box-and-budget"``): what a
    link to the section names."""
    return re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-") or "section"


def reference(ctx: Context, boxes: Sequence[BoxSpec]) -> list[JobRow]:
    ref = ctx.store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
    return reference_rows(ref, boxes, ctx.eps, ctx.spec.settings.penalty_m)


def main_boxes(ctx: Context) -> list[BoxSpec]:
    seen: dict[str, BoxSpec] = {}
    for r in ctx.main:
        if r.box is not None:
            seen.setdefault(r.box.label, r.box)
    return list(seen.values())


def evaluated(r: JobRow) -> bool:
    return r.status == JobStatus.DONE and r.points is not None and len(r.points) > 0


def landscape_grids(ctx: Context) -> list[JobRow]:
    """The evaluated landscape grids (landscape role, else the reference grid worth drawing), at most two."""
    grids = ctx.store.jobs(kind="search", role="landscape", with_points=True, with_trace=False)
    if not grids:
        refs = [r for r in ctx.store.jobs(kind="search", role="reference", with_points=True, with_trace=False)
                if evaluated(r)]
        grids = [interesting(refs, ctx.eps)] if refs else []
    return [g for g in grids if evaluated(g)][:2]


def landscape_runs(ctx: Context, g: JobRow) -> dict[str, JobRow]:
    """Per method (plotting order) the main run drawn over the landscape grid ``g``: on the grid's image, on the
    grid's box, else on the largest box inside it; an evaluation budget before a time budget (a time budget can
    mean thousands of points), then the most evaluations."""
    names = list(g.box.box.names)
    same = [r for r in ctx.runs if r.sample_id == g.sample_id and evaluated(r) and list(r.box.box.names) == names]
    on_box = [r for r in same if r.box.box.bounds() == g.box.box.bounds()]
    if not on_box and same:
        top = max(r.box_level for r in same)
        on_box = [r for r in same if r.box_level == top]
    first: dict[str, JobRow] = {}
    for r in sorted(on_box, key=lambda r: (r.budget.max_seconds is not None, -r.nfev)):
        first.setdefault(r.method, r)
    return {m: first[m] for m in method_order(first)}


def where(ctx: Context, sid: str) -> str:
    dist = ctx.samples[sid].slant_distance_m if sid in ctx.samples else None
    return f"image {sid}" + (f" (slant distance {dist:.0f} m)" if dist else "")


def theta_text(x: Mapping[str, float] | None) -> str:
    """A worst point in short form, parameters by their display names (:data:`~vbl_robust.report.figure_style.
    AXIS_LABELS`): "roll φ = 2.22°, contrast factor α = 1.05"."""
    from .figure_style import axis_label, param_name

    def unit(name: str) -> str:
        u = axis_label(name).rsplit(" (", 1)[-1].rstrip(")") if axis_label(name).endswith(")") else ""
        return "°" if u == "°" else " px" if u == "px" else ""

    return ", ".join(f"{param_name(k)} = {v:.3g}{unit(k)}" for k, v in (x or {}).items())


def sample_cols(ctx: Context, sid: str) -> dict[str, Any]:
    s = ctx.samples.get(sid)
    return {"slant_distance_m": None if s is None else s.slant_distance_m, "envelope": None if s is None else s.envelope}


def interesting(grids: Sequence[JobRow], eps: float) -> JobRow:
    """The 1-D reference grid worth drawing: an image that survives unperturbed (L(0) ≤ ε) but breaches somewhere
    in the box, with its breach region smallest; else the surviving image with the largest worst value."""
    def nominal(g: JobRow) -> float:
        i = int(np.argmin(np.abs(g.points.xs[:, 0])))
        return float(g.points.fs[i]) if np.isfinite(g.points.fs[i]) else math.inf

    ok = [g for g in grids if nominal(g) <= eps]
    if not ok:
        return grids[0]
    breach = [g for g in ok if np.nanmax(g.points.fs) > eps]
    if breach:
        return min(breach, key=lambda g: (np.mean(np.where(np.isfinite(g.points.fs), g.points.fs, math.inf) > eps),
                                          g.sample_index))
    return max(ok, key=lambda g: np.nanmax(g.points.fs))
