"""``vbl-robust risk``: the failure probability of each image when θ follows a distribution over the box
(:mod:`vbl_robust.campaigns.risk`), with its interval and a verdict on "p_fail ≤ τ"; a store and a report like
every campaign."""

from __future__ import annotations

import math
from pathlib import Path

import typer

from ..constants import MAX_IMAGES
from . import options as o
from .common import fail, set_verbosity


def register(app: typer.Typer) -> None:
    @app.command()
    def risk(
        out: Path = typer.Option(Path("runs/risk"), "--out", help="Run directory (results.sqlite, report.html)."),
        n: int | None = typer.Option(None, "--n", "--images", min=1, max=MAX_IMAGES, show_default=False,
                                     help="Number of images (default 20, or all rows of a smaller --lard dataset)."),
        seed: int = o.SEED,
        lard: Path | None = o.LARD,
        width: int = o.WIDTH,
        height: int = o.HEIGHT,
        model: Path | None = o.MODEL,
        trust_model: bool = o.TRUST_MODEL,
        design: str = o.DESIGN,
        engine: str = o.ENGINE,
        device: str = o.DEVICE,
        oracle: bool = o.ORACLE,
        oracle_noise: float = o.ORACLE_NOISE,
        roll: str = typer.Option("15", "--roll", help="Roll range in degrees: '15' (= ±15) or 'lo,hi'; 'none' to omit."),
        contrast: str | None = typer.Option(None, "--contrast", help="Contrast factor range 'lo,hi'."),
        perturb: list[str] | None = typer.Option(None, "--perturb", help="Another perturbation family and its range, "
                                                 "NAME=LO,HI (repeatable), as for audit."),
        dist: list[str] | None = typer.Option(None, "--dist", help="A parameter's distribution over its range: "
                                              "NAME=normal:MEAN,SD (truncated to the range) or NAME=uniform "
                                              "(repeatable; default uniform)."),
        methods: str = typer.Option("mc,guided", "--methods", help="Estimators: mc (Monte Carlo with a sequential "
                                    "test, stops once decided) and guided (stratified over a worst-case search's "
                                    "cells)."),
        max_evals: int = typer.Option(1024, "--max-evals", min=2, max=1_000_000, help="Evaluations per image and "
                                      "estimator (at most 1,000,000)."),
        tau: float = typer.Option(0.01, "--tau", help="The limit on p_fail of the verdict (a fraction, e.g. 0.01)."),
        delta: float = typer.Option(0.05, "--delta", help="1 − confidence of the intervals and the verdict."),
        guide_evals: int = typer.Option(64, "--guide-evals", min=1, help="guided: evaluations of its worst-case "
                                        "search (they count in --max-evals)."),
        pnp: str = typer.Option("ippe_lm", "--pnp", help="PnP solver: ippe_lm, iterative, sqpnp, ippe."),
        executor: str = o.EXECUTOR,
        workers: int = o.WORKERS,
        wait: bool = o.WAIT,
        retry_failed: bool = o.RETRY_FAILED,
        address: str | None = o.ADDRESS,
        csv: Path | None = o.CSV,
        parquet: Path | None = o.PARQUET,
        report: bool = o.REPORT,
        quiet: bool = o.QUIET,
        verbose: bool = o.VERBOSE,
        config: Path | None = o.CONFIG,
    ) -> None:
        """Failure probability per image when θ is drawn from a distribution over the box (turbulence, not a worst
        case): p_fail with a valid interval, a verdict on p_fail ≤ τ, and the rate pooled over the images."""
        from vbl_robust.campaigns import risk_spec
        from vbl_robust.campaigns.risk import RISK_METHODS, parse_dist
        from vbl_robust.campaigns.runner import check_executor

        from .audit import (
            check_exports,
            detector_spec,
            finish,
            load,
            parse_box,
            run_settings,
            run_with_progress,
        )

        quiet = set_verbosity(quiet=quiet, verbose=verbose)
        box = parse_box(roll, contrast, perturb)
        method_list = tuple(m.strip() for m in methods.split(",") if m.strip())
        bad = [m for m in method_list if m not in RISK_METHODS]
        if bad or not method_list or len(set(method_list)) != len(method_list):
            fail(f"--methods {methods}: choose among {', '.join(RISK_METHODS)}, each once")
        for name, v in (("--tau", tau), ("--delta", delta)):
            if not math.isfinite(v):
                fail(f"{name} {v}: must be finite")
        try:
            check_executor(executor, address)
            spec = risk_spec(box, methods=method_list, max_evals=max_evals, seed=seed, dist=parse_dist(dist),
                             tau=tau, delta=delta, guide_evals=guide_evals, pnp=pnp)
        except ValueError as exc:
            fail(str(exc))
        spec, workers = run_settings(spec, "auto", device, workers)
        check_exports(csv, parquet, out)
        det = detector_spec(model, trust_model, oracle, oracle_noise, design, engine, device)
        samples, source = load(n, seed, lard, width, height)
        config = {"command": "risk", "n": len(samples), "seed": seed, "lard": str(lard) if lard else None,
                  "roll": roll, "contrast": contrast, "perturb": list(perturb or []), "dist": list(dist or []),
                  "methods": list(method_list), "max_evals": max_evals, "tau": tau, "delta": delta,
                  "guide_evals": guide_evals, "pnp": pnp, "width": width, "height": height}
        summary = run_with_progress(spec, samples, out, det, executor=executor, address=address, source=source,
                                    config=config, quiet=quiet, workers=workers, wait=wait, retry_failed=retry_failed)
        complete = finish(out, summary, csv=csv, parquet=parquet, report=report, quiet=quiet)
        if not quiet:
            _print_pooled(out)
        if not complete:
            raise typer.Exit(1)


def _print_pooled(out: Path) -> None:
    """Per estimator: the verdict counts and the failure rate pooled over the images."""
    from vbl_robust.campaigns import ResultStore
    from vbl_robust.campaigns.risk import pooled_risk

    with ResultStore.open_existing(out) as store:
        rows = store.jobs(kind="risk", with_points=True, with_trace=False)
    for line in pooled_risk(rows):
        typer.echo(f"{line.method}: {line.images} images, p_fail pooled {100 * line.p_fail:.2f} % "
                   f"[{100 * line.ci.low:.2f}, {100 * line.ci.high:.2f}] ({100 * line.ci.level:g} %); "
                   f"p_fail ≤ {line.tau:g}: holds {line.holds}, violated {line.violated}, undecided "
                   f"{line.undecided}; {line.evaluations} evaluations")
