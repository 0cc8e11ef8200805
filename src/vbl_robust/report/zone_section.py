"""The report's vulnerability-zone section: each main job of a covering method replayed on its stored values
(:func:`vbl_robust.campaigns.replay.job_zones`, no evaluation) and classified, drawn over the landscape, tabulated."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..campaigns.replay import JobZones, ReplayError, job_zones
from ..search.api import METHODS
from ..search.zones import CLASSES, ZoneMap
from ..specs.campaign import CampaignSpec
from ..specs.kinds import JobStatus
from ..store.rows import JobRow
from .figure_style import method_order, style
from .html import esc, table
from .rows import Context, Section, landscape_grids, landscape_runs, where
from .zone_figure import plot_zones

logger = logging.getLogger(__name__)


#: At most this many stored points are replayed for the zones section (whole images, the landscape image first):
#: replay evaluates nothing but re-runs each method's own selection and classifies every cell, about 0.2–0.6 ms
#: per point (so at most about a minute); the rest of a very large run is left to ``vbl-robust zones RUN``.
ZONES_REPLAY_POINTS = 100_000


def _covers(method: str) -> bool:
    cls = METHODS.get(method)
    return cls is not None and cls.covers


def basis_label(zm: ZoneMap) -> str:
    """What a zone map's "ruled out" rests on, in a few words: "sound under L = …" or "estimate — not sound"."""
    if zm.basis == "sound":
        lip = zm.lipschitz
        what = (f"{lip:g} ({zm.norm}-norm of real units)" if not isinstance(lip, tuple)
                else f"({', '.join(f'{v:g}' for v in lip)}) per parameter")
        return f"sound under L = {what}"
    if zm.basis == "estimate":
        return f"estimate — not sound (K̂ = {zm.estimate:.4g}, unit cube)"
    return "no constant — nothing ruled out"


@dataclass(frozen=True)
class Zoned:
    """One main job of a covering method and its zones (None when skipped; ``reason`` says why)."""

    row: JobRow
    zones: JobZones | None
    reason: str = ""

    @property
    def map(self) -> ZoneMap | None:
        return None if self.zones is None else self.zones.zones


def _zones_of(row: JobRow, spec: CampaignSpec) -> Zoned:
    """:func:`~vbl_robust.campaigns.replay.job_zones` on the run's basis: its Lipschitz constant (sound) when it has one, else
    the method's own slope estimate (a map whose cells carry none, a single evaluated cell, keeps no ruled-out
    zone). A replay that fails skips the job, with the reason, and never the report."""
    try:
        try:
            jz = job_zones(row, spec, estimate=spec.settings.lipschitz is None)  # else sound under the run's constant
        except ReplayError:
            raise
        except ValueError:  # cells without a slope estimate (one evaluated cell): classified without a constant
            if spec.settings.lipschitz is not None:
                raise
            jz = job_zones(row, spec)
    except ReplayError as e:
        return Zoned(row, None, f"replay failed: {e}")
    except Exception as e:  # a store this code cannot read must not cost the report
        logger.warning("zones of job %s failed", row.key, exc_info=True)
        return Zoned(row, None, f"{type(e).__name__}: {e}")
    return Zoned(row, jz, "" if jz.zones is not None else jz.note)


def zone_jobs(ctx: Context, first: str | None = None) -> tuple[list[Zoned], list[str]]:
    """The zones of every main job of a method that keeps a cover of its box (DIRECT family, grid), in store order
    per image, image ``first`` (the landscape's) first; and the images left out once :data:`ZONES_REPLAY_POINTS`
    stored points have been replayed."""
    rows = [r for r in ctx.runs if _covers(r.method)]
    by_sample: dict[str, list[JobRow]] = {}
    for r in rows:
        by_sample.setdefault(r.sample_id, []).append(r)
    out: list[Zoned] = []
    left_out: list[str] = []
    spent = 0
    for sid in sorted(by_sample, key=lambda sid: (sid != first, by_sample[sid][0].sample_index)):
        if out and spent >= ZONES_REPLAY_POINTS:
            left_out.append(sid)
            continue
        for r in by_sample[sid]:
            out.append(_zones_of(r, ctx.spec))
            spent += 0 if r.points is None else len(r.points)
    return out, left_out


def zone_lines(jobs: Sequence[Zoned]) -> list[dict[str, Any]]:
    """The zones table: per method (plotting order), box (by level) and budget, the number of jobs with zones, the
    mean and median % of Θ breached / undecided / ruled out over them, the jobs skipped and the bases."""
    groups: dict[tuple[str, str | None, str | None], list[Zoned]] = {}
    for j in jobs:
        groups.setdefault((j.row.method, j.row.box_label, j.row.budget_label), []).append(j)
    methods = method_order(m for m, _, _ in groups)
    # boxes of one parameter set together (a family), by level within it
    params = list(dict.fromkeys(js[0].row.box.box.names for js in groups.values()))
    order = {k: (methods.index(k[0]), params.index(js[0].row.box.box.names), js[0].row.box_level or 0.0)
             for k, js in groups.items()}
    lines = []
    for key in sorted(groups, key=order.__getitem__):
        js = groups[key]
        maps = [j.map for j in js if j.map is not None]
        line: dict[str, Any] = {"method": style(key[0])["label"], "box": key[1], "budget": key[2],
                                "n": len(maps), "skipped": len(js) - len(maps),
                                "basis": ", ".join(sorted({zm.basis for zm in maps}))}
        for c in CLASSES:
            v = 100.0 * np.array([zm.fractions[c] for zm in maps])
            line[f"{c}_mean"] = float(v.mean()) if len(v) else None
            line[f"{c}_median"] = float(np.median(v)) if len(v) else None
        lines.append(line)
    return lines


_ZONE_COLS = [(f"{c}_{stat}", f"{c.replace('_', ' ')} % {stat}", None) for c in CLASSES for stat in ("mean", "median")]


def section_zones(ctx: Context) -> Section | None:
    """Vulnerability zones: the landscape image's zones drawn over its landscape, and the class fractions of Θ
    over every main job of a method that keeps a cover (DIRECT family, grid). Drawn from what the store holds,
    whatever figures the spec declares; no section without such jobs."""
    if not any(_covers(r.method) for r in ctx.runs):
        return None
    grids = landscape_grids(ctx)
    g = grids[0] if grids else None
    jobs, left_out = zone_jobs(ctx, None if g is None else g.sample_id)
    s = Section("Vulnerability zones")
    lip = ctx.spec.settings.lipschitz
    s.html.append(
        "<p>Each main search that keeps a cover of Θ (the DIRECT family, the grid) is replayed on its stored values "
        "(nothing is evaluated again) and each of its cells classified: <b>breached</b> — the cell's evaluated point "
        f"is above ε_safe = {ctx.eps:g} m (an observed fact); <b>ruled out</b> — the value plus L·r (r: the cell's "
        "size) stays ≤ ε_safe, so no point of the cell can breach if L bounds the slope; <b>undecided</b> — the "
        "rest, and every cell whose value is unknown. Fractions are shares of Θ's volume.</p>")
    if lip is not None:
        what = (f"{lip:g} (2-norm of real units)" if not isinstance(lip, tuple)
                else f"({', '.join(f'{v:g}' for v in lip)}) per parameter")
        s.html.append(f'<p class="note">Basis: <b>sound under L = {esc(what)}</b>, the run\'s Lipschitz constant: '
                      "ruled-out zones hold under the assumption that it bounds the objective's.</p>")
    else:
        s.html.append('<p class="warn">Basis: <b>estimate — not sound</b>. The run has no Lipschitz constant, so '
                      "L is each search's own estimate K̂ (GeoRobust's: the largest slope it observed; the grid's: "
                      "the largest between neighbouring nodes), which under-estimates the true constant: ruled-out "
                      "zones are a guess, not a certificate. Give the audit <code>--lipschitz</code> for sound "
                      "zones.</p>")
    s.html.extend(_zone_figures(ctx, g, {j.row.key: j for j in jobs}))
    done = sorted({j.row.sample_id for j in jobs})
    s.html.append(f"<p>Over all main jobs of covering methods ({len(done)} images"
                  + (f"; the other {len(left_out)} image(s) were not replayed: the report replays at most "
                     f"{ZONES_REPLAY_POINTS} stored evaluations, <code>vbl-robust zones RUN</code> every job"
                     if left_out else "") + "): % of Θ per class, mean and median over jobs.</p>")
    s.html.append(table(zone_lines(jobs), [("method", "method", None), ("box", "box", None),
                                           ("budget", "budget", None), ("n", "jobs", None), *_ZONE_COLS,
                                           ("skipped", "skipped", None), ("basis", "basis", None)],
                        left=("method", "box", "budget", "basis")))
    implied = sum(1 for j in jobs if j.map is None and j.row.status == JobStatus.IMPLIED)
    skipped = [j for j in jobs if j.map is None and j.row.status != JobStatus.IMPLIED]
    if implied:
        s.html.append(f"<p>{implied} job(s) implied by a breach at a smaller box of their chain ran no search: no "
                      "zones.</p>")
    if skipped:
        s.html.append(f'<p class="warn">{len(skipped)} job(s) skipped (no zones)'
                      + (", the first 50:" if len(skipped) > 50 else ":") + "</p>")
        s.html.append(table([{"sample_id": j.row.sample_id, "method": j.row.method, "box": j.row.box_label,
                              "budget": j.row.budget_label, "reason": j.reason} for j in skipped[:50]],
                            [("sample_id", "image", None), ("method", "method", None), ("box", "box", None),
                             ("budget", "budget", None), ("reason", "reason", None)],
                            left=("sample_id", "method", "box", "budget", "reason")))
    return s


def _zone_figures(ctx: Context, g: JobRow | None, by_key: dict[Any, JobZones]) -> list[str]:
    """The HTML of the drawn zones: each method's job on the landscape grid ``g``'s image over it, then the table
    of those drawn (a note instead when there is no 1-D or 2-D grid)."""
    if g is None or g.box.box.dim > 2:
        return ['<p class="note">No 1-D or 2-D landscape grid in this run: the zones are not drawn '
                "(<code>vbl-robust zones RUN --plot DIR</code> draws each job's).</p>"]
    out: list[str] = []
    drawn, not_drawn = [], []
    for m, r in landscape_runs(ctx, g).items():
        j = by_key.get(r.key)
        if j is None or j.map is None:
            if j is not None:
                not_drawn.append(f"{style(m)['label']} ({j.reason})")
            continue
        zm = j.map
        box = r.box.box
        inside = np.all((g.points.xs >= box.lower) & (g.points.xs <= box.upper), axis=1)
        name = f"zones_{m}"
        label = basis_label(zm)
        png = plot_zones(zm, ctx.out_dir / "figures" / f"{name}.png",
                         landscape=(g.points.xs[inside], g.points.fs[inside]),
                         title=f"{style(m)['label']} zones on {r.box_label}, image {r.sample_id} — "
                               f"{label.split(' (')[0]}")
        outside = len(j.zones.outside_breaches)
        ground = ("the dense grid's L(θ) (line)" if box.dim == 1
                  else "the dense grid's L(θ) (heat map; dashed: ε_safe)")
        out.append(ctx.figure_file(png, name, (
            f"{esc(style(m)['label'])} on {esc(r.box_label)} (budget {esc(r.budget_label)}; {r.nfev} evaluated), "
            f"{esc(where(ctx, r.sample_id))}: "
            f"{len(zm.zones)} cells over {ground}. Red: breached; grey: undecided; green: ruled out. Basis: "
            f"<b>{esc(label)}</b>." + (f" {outside} breaching evaluation(s) are no cell's centre (not drawn as "
                                       "zones)." if outside else ""))))
        drawn.append({"method": style(m)["label"], "box": r.box_label, "budget": r.budget_label,
                      "nfev": r.nfev, "cells": len(zm.zones),
                      **{c: 100.0 * zm.fractions[c] for c in CLASSES}, "basis": label})
    if not_drawn:
        out.append(f'<p class="warn">Not drawn (no zones): {esc("; ".join(not_drawn))}.</p>')
    if drawn:
        out.append(table(drawn, [("method", "method", None), ("box", "box", None), ("budget", "budget", None),
                                 ("nfev", "evals", None), ("cells", "cells", None),
                                 *[(c, f"{c.replace('_', ' ')} %", None) for c in CLASSES],
                                 ("basis", "basis", esc)], left=("method", "box", "budget", "basis")))
    return out
