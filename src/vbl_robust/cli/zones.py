"""``vbl-robust zones RUN``: the vulnerability zones of a stored run; and ``audit --refine-zones``'s refinement.

The zones of each search job are rebuilt by replaying its method on the stored values
(:func:`vbl_robust.campaigns.replay.replay`: nothing is evaluated) and classified breached / undecided / ruled out
(:mod:`vbl_robust.search.zones`). Output: JSON (one object per job: identity, box, class fractions, zones), CSV (one
row per zone, with its job's identity and fractions) or Markdown (the mean class fractions per method and box);
jobs of methods without a cover (random, Sobol, APGD) are
listed as skipped with the reason.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections import Counter
from pathlib import Path
from typing import Annotated, Any

import typer

from ..atomic import atomic_write
from ..campaigns.refine import refine_run
from ..specs.kinds import Role
from . import options as o
from .common import check_writable, fail, parse_lipschitz

FORMATS = ("json", "csv", "md")
#: ``--role``: the roles whose jobs are zoned (None: every role).
ROLE_CHOICES: dict[str, tuple[Role, ...] | None] = {"all": None, **{r.value: (r,) for r in Role}}

Lipschitz = o.variant(o.Lipschitz, help="A Lipschitz constant of the error (m per unit; one number with --norm, or one "
                      "per parameter): sound zones under that assumption. Default: the run's own --lipschitz, if any.")
Norm = Annotated[str, typer.Option("--norm", help="Norm of a scalar --lipschitz: 2, inf or 1 (real units).")]
Estimate = Annotated[bool, typer.Option("--estimate", help="Classify with each search's own slope estimate "
                                        "(GeoRobust's K̂: NOT sound; labelled an estimate).")]
Threshold = Annotated[float | None, typer.Option("--threshold", help="ε in metres (default: the run's ε_safe).")]
Role = Annotated[str, typer.Option("--role", help="Jobs of this role only: main, reference, landscape or all.")]
Format = Annotated[str, typer.Option("--format", help="json, csv or md (the mean fractions per method and box).")]
Out = Annotated[Path | None, typer.Option("--out", help="Write to this file (default: standard output).")]
Plot = Annotated[Path | None, typer.Option("--plot", help="Also draw each 1-D/2-D job's zones to DIR/<key>.png.")]


def zones(
    run: o.StoredRun, lipschitz: Lipschitz = None, norm: Norm = "2", estimate: Estimate = False,
    threshold: Threshold = None, role: Role = "all", fmt: Format = "json", out: Out = None, plot: Plot = None,
) -> None:
    """Breached / undecided / ruled-out zones of Θ for each search job of a run (replayed, not re-evaluated)."""
    # scipy, torch and matplotlib behind these: imported here, not for ``--help``
    from vbl_robust.campaigns.replay import ReplayError, zones_of_run
    from vbl_robust.report.zone_figure import plot_zones
    from vbl_robust.store.core import ResultStore

    if fmt not in FORMATS:
        fail(f"--format {fmt}: choose json, csv or md")
    if role not in ROLE_CHOICES:
        fail(f"--role {role}: choose main, reference, landscape or all")
    if lipschitz is not None and estimate:
        fail("--lipschitz and --estimate are exclusive (a sound constant, or the searches' own estimate)")
    if norm not in ("2", "inf", "1"):
        fail(f"--norm {norm}: choose 2, inf or 1")
    if threshold is not None and not (math.isfinite(threshold) and threshold > 0):
        fail(f"--threshold {threshold:g}: an error threshold ε in metres must be finite and > 0")
    if plot is not None and plot.exists() and not plot.is_dir():
        fail(f"--plot {plot}: is a file, not a directory")
    if out is not None:
        check_writable("--out", out)
    lip = parse_lipschitz(lipschitz)
    try:
        with ResultStore.open_existing(run) as store:  # a 0-byte store, or one nothing ran into: nothing to zone
            store.require_campaign()
        jobs = zones_of_run(run, roles=ROLE_CHOICES[role], threshold=threshold, lipschitz=lip,
                            norm=norm, estimate=estimate)
    except ReplayError as exc:
        fail(f"replay failed: {exc}")
    except (ValueError, FileNotFoundError) as exc:
        fail(str(exc))
    done = [j for j in jobs if j.zones is not None]
    for line in _notes(jobs):
        typer.secho(line, err=True, fg=typer.colors.YELLOW)
    if fmt == "md":
        from vbl_robust.report.markdown import zones_markdown

        text = zones_markdown(jobs)
    else:
        text = _as_json(run, jobs) if fmt == "json" else _as_csv(done)
    if out is None:
        typer.echo(text, nl=False)
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(out, text)
        typer.echo(f"zones of {len(done)} job(s) ({len(jobs) - len(done)} skipped): {out}", err=True)
    if plot is not None:
        for j in done:
            if j.box is not None and j.box.dim <= 2:
                plot_zones(j.zones, plot / f"{j.key[:16]}.png",
                           title=f"{j.method}, {j.sample_id}, {j.box_label}: {j.zones.describe()[:60]}")


def _notes(jobs: list[Any]) -> list[str]:
    """One line per method and reason, with its count (a campaign of thousands of jobs gives a few lines, not one
    per job); ``--format json`` lists every skipped job and its note."""
    skipped = Counter((j.method, j.note.removeprefix(f"{j.method}: ")) for j in jobs if j.zones is None)
    outside = Counter(j.method for j in jobs if j.zones is not None and j.note)
    return ([f"note: skipped {n} {method} job(s): {why}" for (method, why), n in sorted(skipped.items())]
            + [f"note: {n} {method} job(s) breached at evaluations that are no cell's centre (a batch cut at its "
               "first breach; --format json lists them as outside_breaches)" for method, n in sorted(outside.items())])


def _as_json(run: Path, jobs: list[Any]) -> str:
    body = {"run": str(run), "jobs": [j.to_dict() for j in jobs if j.zones is not None],
            "skipped": [{"key": j.key, "sample_id": j.sample_id, "method": j.method, "role": j.role, "note": j.note}
                        for j in jobs if j.zones is None]}
    return json.dumps(body, indent=1, allow_nan=False) + "\n"


def _as_csv(jobs: list[Any]) -> str:
    names: list[str] = []
    for j in jobs:
        names += [n for n in j.box.names if n not in names]
    cols = ["key", "sample_id", "sample_index", "method", "role", "box_label", "basis", "threshold",
            "fraction_breached", "fraction_undecided", "fraction_ruled_out", "class", "value", "bound", "fraction",
            *(f"{n}_{k}" for n in names for k in ("lower", "upper", "center"))]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for j in jobs:
        zm = j.zones
        fr = zm.fractions
        head = {"key": j.key, "sample_id": j.sample_id, "sample_index": j.sample_index, "method": j.method,
                "role": j.role, "box_label": j.box_label, "basis": zm.basis, "threshold": zm.threshold,
                **{f"fraction_{c}": fr[c] for c in fr}}
        for z in zm.zones:
            row = {**head, "class": z.cls, "value": _cell(z.value), "bound": _cell(z.bound), "fraction": z.fraction}
            for i, n in enumerate(zm.box.names):
                row.update({f"{n}_lower": z.lower[i], f"{n}_upper": z.upper[i], f"{n}_center": z.center[i]})
            w.writerow(row)
    return buf.getvalue()


def _cell(v: float | None) -> str | float:
    return "" if v is None or not math.isfinite(v) else v


# -- audit --refine-zones -----------------------------------------------------------------------------------------
def refine_audit(out: Path, samples: list, detector: Any, budget: int, *,
                 lipschitz: float | tuple[float, ...] | None, quiet: bool = False) -> Path:
    """After an audit: :func:`vbl_robust.campaigns.refine.refine_run`, then how the fractions changed (a table)."""
    from vbl_robust.campaigns.replay import ReplayError  # scipy behind it: not for ``--help``

    try:
        path, refined = refine_run(out, samples, detector, budget, lipschitz=lipschitz)
    except ReplayError as exc:
        fail(f"--refine-zones: replay failed: {exc}")
    except ValueError as exc:
        fail(f"--refine-zones: {exc}")
    if not quiet:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=f"zones refined with {budget} evaluations per job (volume %, before → after)")
        for c in ("image", "method", "evals", "breached", "undecided", "ruled out", "basis"):
            t.add_column(c, justify="left" if c in ("image", "method", "basis") else "right")
        for r in refined:
            b, a = r.refinement.before.fractions, r.refinement.after.fractions
            t.add_row(f"#{r.sample_index}", r.method, str(r.refinement.evaluations),
                      *(f"{100 * b[c]:.1f} → {100 * a[c]:.1f}" for c in ("breached", "undecided", "ruled_out")),
                      r.refinement.after.basis)
        Console().print(t)
    typer.echo(f"refined zones: {path}")
    return path
