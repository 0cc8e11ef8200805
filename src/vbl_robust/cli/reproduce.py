"""``vbl-robust reproduce EXPERIMENT|paper|all``: run one of the paper's experiments, the paper's seven, or all of
them with ours (defaults are the paper's). ``paper`` and ``all`` give each experiment its own run directory under
``--out`` (each resumable on its own) and an ``index.html`` linking their reports; ``--estimate`` prints, from a short measured probe of the detector on this
machine, an upper bound of each experiment's duration (every evaluation budget spent, no early stop) and exits.
"""

from __future__ import annotations

from pathlib import Path

import typer

from .audit import (
    CLOCK_HELP,
    DEVICE_HELP,
    ENGINE_HELP,
    METHOD_OPTION_HELP,
    WORKERS_HELP,
    detector_spec,
    finish,
    load,
    parse_method_options,
    parse_methods,
    run_settings,
    run_with_progress,
    with_method_options,
)
from .common import fail


def _floats(text: str | None, name: str) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise typer.BadParameter(f"{name}: expected comma-separated numbers, got {text!r}") from None
    if not vals or any(v <= 0 for v in vals):
        raise typer.BadParameter(f"{name}: expected numbers > 0, got {text!r}")
    return vals


def planned_work(spec, n_images: int) -> tuple[int, float]:
    """``(evaluations, seconds)`` an experiment can spend on ``n_images``: the evaluation budgets (grids: their
    points) of every job, and the time budgets of the time-bounded ones — an upper bound (early stops and chains
    cut it)."""
    import math

    jobs = spec.expand([(f"probe{i}", "") for i in range(n_images)])
    evals, seconds = 0, 0.0
    for j in jobs:
        if j.kind == "pnp":
            evals += 1
            continue
        counts = (j.options or {}).get("counts")
        if counts:
            evals += math.prod(int(c) for c in counts)
        elif j.budget.max_evals is not None:
            evals += j.budget.max_evals
        if j.budget.max_seconds is not None and j.budget.max_evals is None:
            seconds += j.budget.max_seconds
    return evals, seconds


def probe_rate(det, seconds: float = 5.0) -> float:
    """Evaluations per second of the audit objective (roll ± 15°, contrast) on one synthetic image, measured."""
    import time

    import numpy as np

    from vbl_robust.campaigns.work import detector_for
    from vbl_robust.pipeline import Objective
    from vbl_robust.scenes import generate
    from vbl_robust.space import ParameterBox

    box = ParameterBox({"roll_deg": (-15, 15), "contrast": (0.7, 1.4)})
    obj = Objective(generate(1, seed=0)[0], detector_for(det), box)
    rng = np.random.default_rng(0)
    obj(box.from_unit(rng.random((8, 2))))  # warm-up: model, pixels
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        obj(box.from_unit(rng.random((32, 2))))
        n += 32
    return n / (time.perf_counter() - t0)


def write_index(out: Path, names: list[str], extra: str = "") -> Path:
    """``out/index.html``: one link per experiment report (those that exist), then ``extra`` HTML (the claims)."""
    import html

    items = "".join(
        f'<li><a href="{html.escape(n)}/report.html">{html.escape(n)}</a></li>' if (out / n / "report.html").exists()
        else f"<li>{html.escape(n)} (no report yet: rerun to resume)</li>" for n in names)
    page = (f"<!doctype html><meta charset='utf-8'><title>vbl-robust: the paper's experiments</title>"
            f"<h1>vbl-robust: the paper's experiments</h1><ul>{items}</ul>{extra}")
    (out / "index.html").write_text(page)
    return out / "index.html"


def register(app: typer.Typer) -> None:
    from vbl_robust.campaigns.experiments import EXPERIMENTS, PAPER

    names = ", ".join(EXPERIMENTS)

    def _check_method_options(options: dict, specs: list) -> None:
        ran = set().union(*(spec.search_methods() for spec in specs))
        missing = sorted(set(options) - ran)
        if missing:
            fail(f"--method-option: no experiment here runs method(s) {missing} (they run {sorted(ran)}; see "
                 "--methods)")

    @app.command()
    def reproduce(
        experiment: str = typer.Argument(..., help=f"One of: {names}; 'paper' (the paper's seven) or 'all'."),
        out: Path | None = typer.Option(None, "--out", help="Run directory (default runs/<experiment>)."),
        images: int | None = typer.Option(None, "--images", min=1, help="Number of images (default: the paper's, "
                                          "100; 1000 for pnp-validation)."),
        seed: int = typer.Option(0, "--seed", help="Seed of the image choice and of the searches."),
        lard: Path | None = typer.Option(None, "--lard", help="LARD V2 dataset directory instead of synthetic scenes."),
        width: int = typer.Option(1024, help="Synthetic image width (px)."),
        height: int = typer.Option(1024, help="Synthetic image height (px)."),
        model: Path | None = typer.Option(None, "--model", help="Detector .pt/.onnx (default: the shipped model)."),
        trust_model: bool = typer.Option(False, "--trust-model", help="Allow loading a .pt pickle from outside the package."),
        design: str = typer.Option("auto", "--detector", help="Detector design: auto (the shipped model's own; a "
                                   "user's model as one pass), single (one pass: the paper's pipeline) or twostage."),
        engine: str = typer.Option("auto", "--engine", help=ENGINE_HELP),
        device: str = typer.Option("cpu", "--device", help=DEVICE_HELP),
        oracle: bool = typer.Option(False, "--oracle", help="Use the oracle detector (exact projected corners)."),
        oracle_noise: float = typer.Option(0.0, "--oracle-noise", help="Oracle: fixed per-image corner noise (px)."),
        methods: str | None = typer.Option(None, "--methods", help="Comma-separated methods (default "
                                           "georobust,georobust-av,random,apgd; families: the same less apgd)."),
        method_option: list[str] | None = typer.Option(None, "--method-option", help=METHOD_OPTION_HELP),
        landscape: bool = typer.Option(True, "--landscape/--no-landscape", help="spatial-2d / runtime-2d: the dense "
                                       "61 × 36 grid on the first image (the report's heat map, about 2200 "
                                       "evaluations)."),
        max_evals: int | None = typer.Option(None, "--max-evals", min=1, help="Per-image evaluations of the spatial "
                                             "experiments (default 200)."),
        grid_step: float | None = typer.Option(None, "--grid-step", min=0.0, help="1-D dense-grid reference step in "
                                               "degrees (default 0.05; 0 = no reference)."),
        time_budgets: str | None = typer.Option(None, "--time-budgets", help="Runtime experiments: seconds per image, "
                                                "comma-separated (default 0.1,0.5,1,2,5)."),
        eval_budgets: str | None = typer.Option(None, "--eval-budgets", help="Runtime experiments: evaluations per "
                                                "image (default 10,25,50,100,200)."),
        iterations: int | None = typer.Option(None, "--iterations", min=1, help="Convergence: GeoRobust iterations (30)."),
        family_grid: int | None = typer.Option(None, "--family-grid", min=0, help="Families: fewest points of each "
                                               "family's dense-grid reference over its largest level (default 201; "
                                               "0 = none)."),
        executor: str = typer.Option("local", "--executor", help="local or ray."),
        workers: int = typer.Option(0, "--workers", help=WORKERS_HELP),
        clock: str = typer.Option("auto", "--clock", help=CLOCK_HELP),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address (default: a local Ray)."),
        csv: Path | None = typer.Option(None, "--csv", help="Also export the job rows to CSV."),
        parquet: Path | None = typer.Option(None, "--parquet", help="Also export the job rows to Parquet."),
        report: bool = typer.Option(True, "--report/--no-report", help="Write report.html into --out."),
        estimate: bool = typer.Option(False, "--estimate", help="Print each experiment's expected duration (upper "
                                      "bound, from a measured probe of the detector here) and exit."),
        quiet: bool = typer.Option(False, "--quiet", "-q"),
    ) -> None:
        """Run one of the paper's experiments, or all; rerunning the same command resumes it."""
        from vbl_robust.campaigns.experiments import Options, with_options
        from vbl_robust.campaigns.experiments import experiment as get_experiment

        if executor not in ("local", "ray"):
            fail(f"--executor must be 'local' or 'ray', got {executor!r}")
        try:
            group = {"all": tuple(EXPERIMENTS), "paper": PAPER}.get(experiment)
            exps = [EXPERIMENTS[n] for n in group] if group else [get_experiment(experiment)]
        except ValueError as exc:
            fail(str(exc))
        eb = _floats(eval_budgets, "--eval-budgets")
        opts = with_options(
            Options(), methods=parse_methods(methods) if methods else None, max_evals=max_evals, grid_step_deg=grid_step,
            time_budgets=_floats(time_budgets, "--time-budgets"), eval_budgets=tuple(int(v) for v in eb) if eb else None,
            iterations=iterations, family_grid=family_grid, landscape=None if landscape else (0, 0),
        )
        method_opts = parse_method_options(method_option)
        _check_method_options(method_opts, [exp.build(seed, opts) for exp in exps])
        det = detector_spec(model, trust_model, oracle, oracle_noise, design, engine, device)
        if estimate:
            rate = probe_rate(det)
            typer.echo(f"probe: {rate:.1f} evaluations/s ({det.name}, roll + contrast, one image, this machine)")
            total = 0.0
            for exp in exps:
                n = images or exp.images
                evals, secs = planned_work(exp.build(seed, opts), n)
                t = evals / rate + secs
                total += t
                typer.echo(f"{exp.name:18s} {n:5d} images  ≤ {evals:9d} evaluations  ≤ {t / 3600:6.2f} h")
            typer.echo(f"{experiment if group else exps[0].name:18s} ≤ {total / 3600:.2f} h (upper bound: every "
                       "budget spent, no early stop)")
            return
        root = out or Path("runs") / (experiment if group else exps[0].name)
        for exp in exps:
            spec = exp.build(seed, opts)
            spec = with_method_options(spec, method_opts, strict=False)  # checked over all experiments above
            spec, n_workers = run_settings(spec, clock, device, workers)
            n = images or exp.images
            out_dir = root / exp.name if group else root
            samples, source = load(n, seed, lard, width, height)
            config = {"command": "reproduce", "experiment": exp.name, "images": n, "seed": seed,
                      "lard": str(lard) if lard else None, "options": repr(opts), "width": width, "height": height}
            if method_opts:
                config["method_options"] = method_opts
            summary = run_with_progress(spec, samples, out_dir, det, executor=executor, address=address,
                                        source=source, config=config, quiet=quiet, workers=n_workers)
            finish(out_dir, summary, csv=csv, parquet=parquet, report=report, quiet=quiet)
        if group:
            from vbl_robust.report.claims import claims_html, claims_of, write_claims

            typer.echo(f"claims: {write_claims(root)}")
            typer.echo(f"index: {write_index(root, [e.name for e in exps], claims_html(claims_of(root), str(root)))}")
