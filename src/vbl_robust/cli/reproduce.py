"""``vbl-robust reproduce EXPERIMENT``: run one of the paper's experiments (defaults are the paper's)."""

from __future__ import annotations

from pathlib import Path

import typer

from .audit import ENGINE_HELP, detector_spec, finish, load, parse_methods, run_with_progress
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


def register(app: typer.Typer) -> None:
    from vbl_robust.campaigns.experiments import EXPERIMENTS

    names = ", ".join(EXPERIMENTS)

    @app.command()
    def reproduce(
        experiment: str = typer.Argument(..., help=f"One of: {names}."),
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
        oracle: bool = typer.Option(False, "--oracle", help="Use the oracle detector (exact projected corners)."),
        oracle_noise: float = typer.Option(0.0, "--oracle-noise", help="Oracle: fixed per-image corner noise (px)."),
        methods: str | None = typer.Option(None, "--methods", help="Comma-separated methods (default georobust,random,apgd)."),
        max_evals: int | None = typer.Option(None, "--max-evals", min=1, help="Per-image evaluations of the spatial "
                                             "experiments (default 200)."),
        grid_step: float | None = typer.Option(None, "--grid-step", min=0.0, help="1-D dense-grid reference step in "
                                               "degrees (default 0.05; 0 = no reference)."),
        time_budgets: str | None = typer.Option(None, "--time-budgets", help="Runtime experiments: seconds per image, "
                                                "comma-separated (default 0.1,0.5,1,2,5)."),
        eval_budgets: str | None = typer.Option(None, "--eval-budgets", help="Runtime experiments: evaluations per "
                                                "image (default 10,25,50,100,200)."),
        iterations: int | None = typer.Option(None, "--iterations", min=1, help="Convergence: GeoRobust iterations (30)."),
        executor: str = typer.Option("local", "--executor", help="local or ray."),
        address: str | None = typer.Option(None, "--address", help="Ray cluster address (default: a local Ray)."),
        csv: Path | None = typer.Option(None, "--csv", help="Also export the job rows to CSV."),
        parquet: Path | None = typer.Option(None, "--parquet", help="Also export the job rows to Parquet."),
        report: bool = typer.Option(True, "--report/--no-report", help="Write report.html into --out."),
        quiet: bool = typer.Option(False, "--quiet", "-q"),
    ) -> None:
        """Run one of the paper's experiments; rerunning the same command resumes it."""
        from vbl_robust.campaigns.experiments import Options, with_options
        from vbl_robust.campaigns.experiments import experiment as get_experiment

        try:
            exp = get_experiment(experiment)
        except ValueError as exc:
            fail(str(exc))
        if executor not in ("local", "ray"):
            fail(f"--executor must be 'local' or 'ray', got {executor!r}")
        eb = _floats(eval_budgets, "--eval-budgets")
        opts = with_options(
            Options(), methods=parse_methods(methods) if methods else None, max_evals=max_evals, grid_step_deg=grid_step,
            time_budgets=_floats(time_budgets, "--time-budgets"), eval_budgets=tuple(int(v) for v in eb) if eb else None,
            iterations=iterations,
        )
        spec = exp.build(seed, opts)
        n = images or exp.images
        out_dir = out or Path("runs") / exp.name
        det = detector_spec(model, trust_model, oracle, oracle_noise, design, engine)
        samples, source = load(n, seed, lard, width, height)
        config = {"command": "reproduce", "experiment": exp.name, "images": n, "seed": seed,
                  "lard": str(lard) if lard else None, "options": repr(opts), "width": width, "height": height}
        summary = run_with_progress(spec, samples, out_dir, det, executor=executor, address=address, source=source,
                                    config=config, quiet=quiet)
        finish(out_dir, summary, csv=csv, parquet=parquet, report=report, quiet=quiet)
