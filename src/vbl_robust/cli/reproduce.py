"""``vbl-robust reproduce EXPERIMENT|paper|all``: run one of the paper's experiments, the paper's seven, or all of
them with ours (defaults are the paper's). ``paper`` and ``all`` give each experiment its own run directory under
``--out`` (each resumable on its own) and an ``index.html`` linking their reports; ``--estimate`` prints
(:mod:`vbl_robust.paper.estimate`), from a short measured probe of the detector on this
machine and the breach rates of its first images, each experiment's expected duration and an upper bound (every
evaluation budget spent, no early stop), and exits.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from ..consent import refuse_without_consent
from ..constants import MAX_IMAGES
from ..paper.estimate import PROBE_IMAGES, Probe, expected_seconds, measured_remaining, planned_work, probe
from ..paper.experiments import EXPERIMENTS, PAPER, Options, experiment, with_options
from . import options as o
from .common import (
    fail,
    one_line,
    parse_method_options,
    parse_methods,
    set_verbosity,
    with_method_options,
)
from .config import parameters, run_config
from .requests import DetectorRequest, ExportRequest, ImagesRequest, RunRequest

Experiment = Annotated[str, typer.Argument(help=f"One of: {', '.join(EXPERIMENTS)}; 'paper' (the paper's seven) or "
                                           "'all'.")]
Out = o.variant(o.Out, Path | None, help="Run directory (default runs/<experiment>).")
Images = Annotated[int | None, typer.Option("--images", min=1, max=MAX_IMAGES, help="Number of images (default: the "
                                            "paper's, 100; 1000 for pnp-validation).")]
Methods = o.variant(o.Methods, str | None, help="Comma-separated methods (default georobust,georobust-av,random,"
                    "apgd; families: the same less apgd).")
Landscape = o.variant(o.Landscape, bool, help="spatial-2d / runtime-2d: the dense 61 × 36 grid on the first image "
                      "(the report's heat map, about 2200 evaluations).")
MaxEvals = o.variant(o.MaxEvals, min=1, help="Per-image evaluations of the spatial experiments (default 200).")
GridStep = Annotated[float | None, typer.Option("--grid-step", min=0.0, help="1-D dense-grid reference step in degrees "
                                                "(default 0.05; 0 = no reference).")]
TimeBudgets = Annotated[str | None, typer.Option("--time-budgets", help="Runtime experiments: seconds per image, "
                                                 "comma-separated (default 0.1,0.5,1,2,5).")]
EvalBudgets = Annotated[str | None, typer.Option("--eval-budgets", help="Runtime experiments: evaluations per image "
                                                 "(default 10,25,50,100,200).")]
Iterations = Annotated[int | None, typer.Option("--iterations", min=1, help="Convergence: GeoRobust iterations (30).")]
FamilyGrid = Annotated[int | None, typer.Option("--family-grid", min=0, help="Families: fewest points of each "
                                                "family's dense-grid reference over its largest level (default 201; "
                                                "0 = none).")]
ResumeFrom = Annotated[Path | None, typer.Option(
    "--resume-from", help="A bundle written with `vbl-robust bundle --stores`: its stores seed the run directories "
    "under --out that have none yet, so the run goes on where the bundle's ended.")]
CheckAgainst = Annotated[Path | None, typer.Option(
    "--check-against", help="After each experiment, check that its rows are those of an earlier run or bundle of it "
    "(a run directory or a `vbl-robust bundle` output; for paper/all the directory holding one per experiment): same "
    "keys, verdicts, counts and worst points, worst errors within 1e-3 relative; rows of time budgets are not "
    "compared. Exit code 1 when one differs.")]
Estimate = Annotated[bool, typer.Option("--estimate", help="Print each experiment's expected duration (from a measured "
                                        "probe of the detector here and the breach rates of the first images) and its "
                                        "upper bound, and exit.")]
ProbeSeconds = Annotated[float, typer.Option("--probe-seconds", min=0.01, help="--estimate: seconds each "
                                             "evaluation-rate probe runs (black box, gradient).")]


def reproduce(
    experiment: Experiment, out: Out = None, images: Images = None, seed: o.Seed = 0, lard: o.Lard = None,
    width: o.Width = 1024, height: o.Height = 1024,
    model: o.Model = None, trust_model: o.TrustModel = False, design: o.Design = "auto", engine: o.Engine = "auto",
    detector_plugin: o.DetectorPlugin = None, plugin_digest: o.PluginDigest = None,
    device: o.Device = "cpu", oracle: o.Oracle = False, oracle_noise: o.OracleNoise = 0.0,
    methods: Methods = None, method_option: o.MethodOption = None, landscape: Landscape = True,
    max_evals: MaxEvals = None, grid_step: GridStep = None, time_budgets: TimeBudgets = None,
    eval_budgets: EvalBudgets = None, iterations: Iterations = None, family_grid: FamilyGrid = None,
    executor: o.Executor = "local", workers: o.Workers = 0, clock: o.Clock = "auto", wait: o.Wait = False,
    retry_failed: o.RetryFailed = False, resume_from: ResumeFrom = None, check_against: CheckAgainst = None,
    address: o.Address = None, allow_unmeasured: o.AllowUnmeasured = False, csv: o.Csv = None, parquet: o.Parquet = None, report: o.Report = True,
    estimate: Estimate = False, probe_seconds: ProbeSeconds = 5.0,
    quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
) -> None:
    """Run one of the paper's experiments, or all; rerunning the same command resumes it."""
    params = parameters()
    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    run = RunRequest.of(params)
    run.check()
    group, exps = _experiments(experiment)
    eb = _floats(eval_budgets, "--eval-budgets")
    if grid_step is not None and not math.isfinite(grid_step):  # inf passes the option's range
        fail(f"--grid-step {grid_step}: a step in degrees must be finite (0 = no reference)")
    opts = with_options(
        Options(), methods=parse_methods(methods) if methods else None, max_evals=max_evals, grid_step_deg=grid_step,
        time_budgets=_floats(time_budgets, "--time-budgets"), eval_budgets=tuple(int(v) for v in eb) if eb else None,
        iterations=iterations, family_grid=family_grid, landscape=None if landscape else (0, 0),
    )
    exports = ExportRequest.of(params)
    exports.check(out)
    method_opts = parse_method_options(method_option)
    _check_method_options(method_opts, [exp.build(seed, opts) for exp in exps])
    det = DetectorRequest.of(params).spec()
    images_of = ImagesRequest.of(params, n=images)
    root = out or Path("runs") / (experiment if group else exps[0].name)
    if estimate:
        run_spec, n_workers = run.settings(exps[0].build(seed, opts), device)
        probe_samples = ImagesRequest.of(params, n=None).load(default=PROBE_IMAGES)[0]  # --images: the run's
        _estimate(exps, opts, seed, images, det, probe_samples, n_workers, experiment if group else "", probe_seconds,
                  run_spec.settings.clock, root)
        return
    if resume_from is not None and not resume_from.is_dir():
        fail(f"--resume-from {resume_from}: not a directory")
    if resume_from is not None:
        from vbl_robust.store.core import PACKED

        if not any((resume_from / exp.name / PACKED).is_file() for exp in exps):  # a run, or a bundle without --stores
            fail(f"--resume-from {resume_from}: holds no packed store of {', '.join(e.name for e in exps)} "
                 f"(<experiment>/{PACKED}, written by `vbl-robust bundle --stores`)")
        _refuse_code(resume_from, [exp.name for exp in exps], trust_model)
    references = {exp.name: _reference(check_against, exp.name) for exp in exps} if check_against else {}
    differ = incomplete = False  # an incomplete experiment does not stop the next ones; the exit code says it
    for exp in exps:
        spec = with_method_options(exp.build(seed, opts), method_opts, strict=False)  # checked over all above
        spec, n_workers = run.settings(spec, device)
        out_dir = root / exp.name if group else root
        if resume_from is not None:
            _restore(resume_from, exp.name, out_dir)
        samples, source = images_of.load(default=exp.images)
        config = run_config("reproduce", experiment=exp.name, images=len(samples), options=repr(opts),
                            **({"method_options": method_opts} if method_opts else {}))
        summary = run.run(spec, samples, out_dir, det, source=source, config=config, quiet=quiet, workers=n_workers)
        incomplete |= not exports.finish(out_dir, summary, quiet=quiet, allow_unmeasured=allow_unmeasured)
        if references:
            differ |= _check(exp.name, out_dir, references[exp.name])
    if group:
        from vbl_robust.paper import claims, claims_page

        typer.echo(f"claims: {claims.write_claims(root)}")
        page = claims_page.claims_html(claims.claims_of(root), str(root))
        typer.echo(f"index: {claims_page.write_index(root, [e.name for e in exps], page)}")
    if differ or incomplete:
        raise typer.Exit(1)


def _experiments(name: str) -> tuple[tuple[str, ...] | None, list]:
    """``reproduce NAME``'s experiments: the group's names (``all``, ``paper``; None for one experiment) and the
    experiments, or one line."""
    group = {"all": tuple(EXPERIMENTS), "paper": PAPER}.get(name)
    with one_line(ValueError):
        return group, [EXPERIMENTS[n] for n in group] if group else [experiment(name)]


def _check_method_options(options: dict, specs: list) -> None:
    """Every ``--method-option`` names a method that some experiment here runs."""
    ran = set().union(*(spec.search_methods() for spec in specs))
    missing = sorted(set(options) - ran)
    if missing:
        fail(f"--method-option: no experiment here runs method(s) {missing} (they run {sorted(ran)}; see --methods)")


def _refuse_code(bundle: Path, names: list[str], trust: bool) -> None:
    """``--resume-from``: one line, before anything runs or is restored, when a packed store of the bundle names a
    detector that is code (a factory, a .pt outside the package) and ``trust`` (--trust-model) is not given."""
    from vbl_robust.store.core import PACKED, ResultStore

    for name in names:
        packed = bundle / name / PACKED
        if packed.is_file():
            with one_line(ValueError, prefix=f"--resume-from {bundle}: "):
                with ResultStore.open_existing(packed) as stored:
                    detector = stored.require_campaign().detector if stored.holds_campaign() else {}
                refuse_without_consent(detector or {}, trust, where=f"{name}: ")


def _restore(bundle: Path, name: str, out_dir: Path) -> None:
    """``--resume-from``: the bundle's packed store of experiment ``name`` seeds ``out_dir`` if it has none yet."""
    from vbl_robust.store.core import PACKED
    from vbl_robust.store.pack import restore_store

    packed = bundle / name / PACKED
    with one_line(ValueError, prefix=f"--resume-from {bundle}: "):
        restored = restore_store(packed, out_dir)
    if restored:
        typer.echo(f"{name}: store restored from {packed}")



def _floats(text: str | None, name: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))  # "0.1," (a stray comma) is no number either
    except ValueError:
        raise typer.BadParameter(f"{name}: expected comma-separated numbers, got {text!r}") from None
    if not vals or any(not math.isfinite(v) or v <= 0 for v in vals):
        raise typer.BadParameter(f"{name}: expected finite numbers > 0, got {text!r}")
    return vals


def _estimate(exps: list, opts: Any, seed: int, images: int | None, det: Any, probe_samples: list, workers: int,
              group: str, probe_seconds: float, clock: str = "wall", root: Path | None = None) -> None:
    """Print each experiment's expected duration and its upper bound (:mod:`vbl_robust.paper.estimate`), the
    probe's rates measured on the run's ``clock`` (process: CPU seconds, the durations of an idle machine)."""
    from vbl_robust.store.core import ResultStore

    specs = [exp.build(seed, opts) for exp in exps]
    pr = probe(det, specs, probe_samples, seconds=probe_seconds, clock=clock)
    unit = "CPU second (process clock: the rate of an idle core)" if clock == "process" else "s"
    typer.echo(f"probe: {pr.rate:.1f} evaluations per {unit} black box, {pr.grad_rate:.1f} with a gradient "
               f"({det.name}, one thread); breach shares of {len(pr.breach)} early-stopping boxes on "
               f"{len(probe_samples)} probe images; {workers} worker(s)")
    if pr.how:
        typer.echo(f"probe rates: {pr.how}")
    total = bound = 0.0
    for exp, spec in zip(exps, specs, strict=True):
        n = images or exp.images
        evals, _ = planned_work(spec, n)
        t = expected_seconds(spec, n, pr, workers)
        ub = expected_seconds(spec, n, Probe(pr.rate, pr.grad_rate), workers)
        total, bound = total + t, bound + ub
        run = None if root is None else (root / exp.name if group else root)
        left = ""
        if run is not None and (run / "results.sqlite").is_file():  # under way: its own pace
            with ResultStore.open_existing(run) as store:
                rows = store.jobs(with_trace=False)
            jobs_left, secs = measured_remaining(spec, n, rows, pr, workers)
            left = f"  (under way: {jobs_left} jobs left, ≈ {secs / 3600:.2f} h at its stored jobs' pace)"
        typer.echo(f"{exp.name:18s} {n:5d} images  ≤ {evals:9d} evaluations  ≈ {t / 3600:6.2f} h expected  "
                   f"≤ {ub / 3600:6.2f} h{left}")
    typer.echo(f"{group or exps[0].name:18s} ≈ {total / 3600:.2f} h expected, ≤ {bound / 3600:.2f} h (upper bound: "
               "every budget spent, no early stop)")


def _reference(root: Path, name: str) -> Path:
    """``--check-against``: where experiment ``name``'s earlier rows are (``root/name`` or ``root`` itself: a run
    directory with a results store, a bundle's experiment directory with ``jobs.parquet``, or that file); refused
    before any work when there is none."""
    from vbl_robust.store.core import STORE

    for p in (root / name, root):
        if (p.is_dir() and ((p / STORE).is_file() or (p / "jobs.parquet").is_file())) or (
                p.is_file() and p.suffix == ".parquet"):
            return p
    fail(f"--check-against {root}: no results store or jobs.parquet of {name} there (nor in {root / name})")
    raise AssertionError  # unreachable: fail exits


def _check(name: str, run: Path, reference: Path) -> bool:
    """Print how the rows of ``run`` compare with ``reference``'s (:func:`~vbl_robust.paper.bundle.compare_runs`):
    findings changed (status, verdict, a row missing) apart from numeric drift (same findings, other counts or
    worst errors); True only when a finding changed."""
    from vbl_robust.paper.bundle import compare_runs

    c = compare_runs(run, reference)
    first = f" (first: {', '.join(c['differ'][:3])})" if c["differ"] else ""
    drift = (f"; {len(c['drift'])} with numeric drift only (same status and verdict; worst error moved by at most "
             f"{c['drift_m']:.3g} m)" if c["drift"] else "")
    typer.echo(f"{name}: checked against {reference}: {c['rows']} rows, {c['common']} found there, "
               f"{len(c['differ'])} with another finding{first}{drift}")
    return bool(c["differ"])
