"""``vbl-robust risk``: the failure probability of each image when θ follows a distribution over the box
(:mod:`vbl_robust.risk`), with its interval and a verdict on "p_fail ≤ τ"; a store and a report like
every campaign."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from vbl_robust.campaigns.audit import risk_spec

from . import options as o
from .common import fail, one_line, set_verbosity
from .config import parameters, run_config
from .requests import BoxRequest, DetectorRequest, ExportRequest, ImagesRequest, RunRequest

Contrast = o.variant(o.Contrast, help="Contrast factor range 'lo,hi'.")
Perturb = o.variant(o.Perturb, help="Another perturbation family and its range, NAME=LO,HI (repeatable), as for "
                    "audit.")
Dist = Annotated[list[str] | None, typer.Option("--dist", help="A parameter's distribution over its range: "
                                                "NAME=normal:MEAN,SD (truncated to the range) or NAME=uniform "
                                                "(repeatable; default uniform).")]
Methods = o.variant(o.Methods, help="Estimators: mc (Monte Carlo with a sequential test, stops once decided) and "
                    "guided (stratified over a worst-case search's cells).")
MaxEvals = o.variant(o.MaxEvals, int, min=2, max=1_000_000, help="Evaluations per image and estimator (at most "
                     "1,000,000).")
Tau = Annotated[float, typer.Option("--tau", help="The limit on p_fail of the verdict (a fraction, e.g. 0.01).")]
Delta = Annotated[float, typer.Option("--delta", help="1 − confidence of the intervals and the verdict.")]
GuideEvals = Annotated[int, typer.Option("--guide-evals", min=1, help="guided: evaluations of its worst-case search "
                                         "(they count in --max-evals).")]


def risk(
    out: o.Out = Path("runs/risk"), n: o.Images = None, seed: o.Seed = 0, lard: o.Lard = None,
    width: o.Width = 1024, height: o.Height = 1024,
    model: o.Model = None, trust_model: o.TrustModel = False, design: o.Design = "auto", engine: o.Engine = "auto",
    detector_plugin: o.DetectorPlugin = None, plugin_digest: o.PluginDigest = None,
    device: o.Device = "cpu", oracle: o.Oracle = False, oracle_noise: o.OracleNoise = 0.0,
    roll: o.Roll = "15", contrast: Contrast = None, perturb: Perturb = None, dist: Dist = None,
    methods: Methods = "mc,guided", max_evals: MaxEvals = 1024, tau: Tau = 0.01, delta: Delta = 0.05,
    guide_evals: GuideEvals = 64, pnp: o.Pnp = "ippe_lm",
    executor: o.Executor = "local", workers: o.Workers = 0, wait: o.Wait = False,
    retry_failed: o.RetryFailed = False, address: o.Address = None, allow_unmeasured: o.AllowUnmeasured = False,
    csv: o.Csv = None, parquet: o.Parquet = None, report: o.Report = True,
    quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
) -> None:
    """Failure probability per image when θ is drawn from a distribution over the box (turbulence, not a worst
    case): p_fail with a valid interval, a verdict on p_fail ≤ τ, and the rate pooled over the images."""
    from vbl_robust.risk import RISK_METHODS, parse_dist

    params = parameters()
    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    box = BoxRequest.of(params).spec()
    method_list = tuple(m.strip() for m in methods.split(","))
    bad = [m for m in method_list if m not in RISK_METHODS]  # "mc," (a stray comma) too
    if bad or not method_list or len(set(method_list)) != len(method_list):
        fail(f"--methods {methods}: choose among {', '.join(RISK_METHODS)}, each once")
    for name, v in (("--tau", tau), ("--delta", delta)):
        if not math.isfinite(v):
            fail(f"{name} {v}: must be finite")
    run = RunRequest.of(params)
    run.check()
    with one_line(ValueError):
        spec = risk_spec(box, methods=method_list, max_evals=max_evals, seed=seed,
                         dist=parse_dist(dist, box.box.names),
                         tau=tau, delta=delta, guide_evals=guide_evals, pnp=pnp)
    spec, workers = run.settings(spec, device)
    exports = ExportRequest.of(params)
    exports.check(out)
    det = DetectorRequest.of(params).spec()
    samples, source = ImagesRequest.of(params).load()
    config = run_config("risk", n=len(samples), perturb=list(perturb or []), dist=list(dist or []),
                        methods=list(method_list))
    summary = run.run(spec, samples, out, det, source=source, config=config, quiet=quiet, workers=workers)
    complete = exports.finish(out, summary, quiet=quiet, allow_unmeasured=allow_unmeasured)
    if not quiet:
        _print_pooled(out)
    if not complete:
        raise typer.Exit(1)


def _print_pooled(out: Path) -> None:
    """Per estimator: the verdict counts and the failure rate pooled over the images."""
    from vbl_robust.analysis.risk import pooled_risk
    from vbl_robust.store.core import ResultStore

    with ResultStore.open_existing(out) as store:
        rows = store.jobs(kind="risk", with_points=True, with_trace=False)
    for line in pooled_risk(rows):
        typer.echo(f"{line.method}: {line.images} images, p_fail pooled {100 * line.p_fail:.2f} % "
                   f"[{100 * line.ci.low:.2f}, {100 * line.ci.high:.2f}] ({100 * line.ci.level:g} %); "
                   f"p_fail ≤ {line.tau:g}: holds {line.holds}, violated {line.violated}, undecided "
                   f"{line.undecided}; {line.evaluations} evaluations")
