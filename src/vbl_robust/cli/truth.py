"""``vbl-robust truth RUN``: the dense grid over a run's largest box on the images every method left surviving
(:mod:`vbl_robust.analysis.truth`), a resumable campaign beside the run (``RUN-truth``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..specs.kinds import SourceKind
from . import options as o
from .common import fail, from_config, one_line, set_verbosity
from .config import parameters, run_config
from .requests import ExportRequest, RunRequest

Run = Annotated[Path, typer.Argument(help="A run directory (e.g. runs/paper/spatial-2d).")]
Counts = Annotated[str, typer.Option("--counts", help="Grid points per parameter of the run's largest box, "
                                     "comma-separated (e.g. 61,31: 1° × 0.07 over ±30° × [0.4, 2.5]).")]
Out = o.variant(o.Out, Path | None, help="The truth run's directory (default: RUN-truth).")


def truth(
    ctx: typer.Context, run: Run, counts: Counts, out: Out = None, trust_model: o.TrustModel = False,
    workers: o.Workers = 0, wait: o.Wait = False, report: o.Report = True, quiet: o.Quiet = False,
    verbose: o.Verbose = False, config: o.Config = None,
) -> None:
    """Dense grid on the images every method of RUN left surviving at its largest box: is "no breach found"
    true? Prints the true survival there and the true breaches each method missed."""
    from vbl_robust.analysis.truth import (
        TRUTH_SUFFIX,
        load_run_samples,
        survivors_of_every_method,
        true_survival,
        truth_spec,
    )
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.store.core import ResultStore
    from vbl_robust.store.merge import store_file

    params = parameters()
    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    if trust_model and from_config("trust_model"):  # consent to run the store's code is the user's, not a file's
        fail("--trust-model: give it on the command line; a --config file cannot consent to run a store's code")
    try:
        grid = tuple(int(c) for c in counts.split(","))
    except ValueError:
        fail(f"--counts {counts}: expected comma-separated integers")
    out = out if out is not None else run.with_name(run.name + TRUTH_SUFFIX)
    if store_file(out).resolve() == store_file(run).resolve():
        fail(f"--out {out}: is the run itself; the truth run goes beside it (default {run.name}{TRUTH_SUFFIX})")
    with one_line():
        with ResultStore.open_existing(run) as store:
            # the run's detector is data from its store: one that names code (a factory, a .pt) is refused first,
            # before anything else is read, unless --trust-model
            det = DetectorSpec.from_identity(store.require_campaign().detector or {}, trust=trust_model,
                                             where=f"{run}: ")
            run_spec, box, methods, keep = survivors_of_every_method(store)
            samples = load_run_samples(store, keep)
        spec = truth_spec(run_spec, box, grid)
        spec.check()
    if not samples:
        typer.echo(f"{run}: every image is breached by some method at {box.label}; nothing to grid")
        return
    running = RunRequest.of(params)
    spec, n_workers = running.settings(spec, str(det.options.get("device", "cpu")))
    typer.echo(f"{len(samples)} images every method ({', '.join(methods)}) left surviving at {box.label}; "
               f"grid {' × '.join(map(str, grid))}")
    summary = running.run(spec, samples, out, det, source={"kind": SourceKind.TRUTH.value, "run": str(run), "samples": keep},
                          config=run_config("truth", counts=list(grid)), quiet=quiet, workers=n_workers)
    complete = ExportRequest.of(params).finish(out, summary, quiet=True, allow_unmeasured=False)
    t = true_survival(run, out)
    typer.echo(f"{t.box_label}: {t.gridded} of {t.survivors_any} survivors gridded, {t.grid_breaches} breached "
               f"by the grid; true survival "
               + (f"{t.true_survivors} of {t.images}" if t.true_survivors is not None else "not known yet")
               + "; true breaches missed: " + ", ".join(f"{m} {k}" for m, k in t.missed.items()))
    if not complete:
        raise typer.Exit(1)

