"""``vbl-robust audit`` (the main job) and ``vbl-robust demo`` (a small audit on the defaults, with its report)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from vbl_robust.campaigns.experiments import AUDIT_METHODS
from vbl_robust.constants import MAX_EVALS, MAX_IMAGES
from vbl_robust.perturb.registry import known

from . import options as o
from .common import (
    detector_spec,
    fail,
    one_line,
    parse_box,
    parse_lipschitz,
    parse_method_options,
    parse_methods,
    set_verbosity,
    with_method_options,
)
from .run import (
    check_executor,
    check_exports,
    finish,
    load,
    load_sequence_samples,
    run_settings,
    run_with_progress,
)

#: Fixed corner noise of the demo's oracle (``--oracle``, or no validated model installed): exact corners make
#: L(θ) flat in roll (< 1 cm), which shows nothing; 1 px is about what a good detector achieves.
DEMO_ORACLE_NOISE_PX = 1.0

# -- audit's own options ------------------------------------------------------------------------------------------
Contrast = Annotated[str | None, typer.Option("--contrast", help="Contrast factor range 'lo,hi' (e.g. 0.7,1.4).")]
Perturb = Annotated[list[str] | None, typer.Option(
    "--perturb", help="Another perturbation family and its range, NAME=LO,HI (repeatable; a bare NAME takes its "
    f"plausible default range): {known()} (roll_deg here replaces --roll; contrast here or in --contrast, not both).")]
Methods = Annotated[str, typer.Option("--methods", help="Comma-separated search methods.")]
MaxEvals = Annotated[int | None, typer.Option("--max-evals", min=0, max=MAX_EVALS, help="Evaluations per image and "
                                              "method (0 = no evaluation cap: then give --max-seconds).")]
MaxSeconds = Annotated[float | None, typer.Option("--max-seconds", min=0.0, help="Seconds per image and method.")]
EarlyStop = Annotated[bool, typer.Option("--early-stop/--no-early-stop", help="Stop an image's search at its first "
                                         "breach (answers 'is there a breach?').")]
Lipschitz = Annotated[str | None, typer.Option("--lipschitz", help="Lipschitz constant of the error (m per unit, one "
                                               "number or one per parameter): enables 'certified' verdicts.")]
Landscape = Annotated[bool | None, typer.Option(
    "--landscape/--no-landscape", help="Dense grid on the first image for the report's landscape figure (default: "
    "on; with --sequences off, as each grid point costs every frame of the first sequence).")]
Sequences = Annotated[str | None, typer.Option(
    "--sequences", help="Audit approach sequences instead of images: a number N (generated) or a LARD V2 directory "
    "grouped into sequences; one θ is held over each sequence (see --sustain).")]
MonitorResidual = Annotated[float | None, typer.Option(
    "--monitor-residual", help="A runtime monitor: a pose whose PnP reprojection residual (RMS, image pixels) is "
    "above this is a flagged failure, not a pose (measure what it flags and rejects: BENCHMARKS, monitors).")]
MonitorSigma = Annotated[float | None, typer.Option(
    "--monitor-sigma", help="A runtime monitor for a detector that says how sure it is (a YOLO26-pose network: "
    "per-corner σ): a pose whose corners' σ propagated through PnP is above this many metres is a flagged failure, "
    "not a pose (measure what it flags and rejects: BENCHMARKS, monitors). Not with gradient searches (apgd).")]
Target = Annotated[str, typer.Option(
    "--target", help="What the searches look for: any (every breach; a flagged failure — no detection, low "
    "confidence, PnP failed — counts 5000 m, as in the paper) or misleading (a flagged failure counts 0 m, as safe: "
    "every method hunts the worst confident pose, the hazardously misleading error).")]
Sustain = Annotated[int, typer.Option("--sustain", min=1, help="With --sequences: frames the error must hold (the "
                                      "worst error sustained over K consecutive frames).")]
Frames = Annotated[int | None, typer.Option("--frames", min=1, help="With --sequences N: frames per sequence "
                                            "(default 20).")]
Rate = Annotated[float | None, typer.Option("--rate", help="With --sequences: frame rate in Hz (generated sequences; "
                                            "LARD data without times; default 10).")]
RefineZones = Annotated[int, typer.Option(
    "--refine-zones", min=0, help="After the search: spend this many more evaluations per main DIRECT-family/grid "
    "job inside its undecided zones (GeoRobust per zone, largest first) and report how the breached / undecided / "
    "ruled-out fractions changed (zones_refined.json; under --lipschitz, else the search's own estimate).")]


def audit(
    out: o.Out = Path("runs/audit"), n: o.Images = None, seed: o.Seed = 0, lard: o.Lard = None,
    width: o.Width = 1024, height: o.Height = 1024,
    model: o.Model = None, trust_model: o.TrustModel = False, design: o.Design = "auto", engine: o.Engine = "auto",
    detector_plugin: o.DetectorPlugin = None, plugin_digest: o.PluginDigest = None,
    device: o.Device = "cpu", oracle: o.Oracle = False, oracle_noise: o.OracleNoise = 0.0,
    roll: o.Roll = "15", contrast: Contrast = None, perturb: Perturb = None,
    methods: Methods = ",".join(AUDIT_METHODS), method_option: o.MethodOption = None,
    max_evals: MaxEvals = 200, max_seconds: MaxSeconds = None, early_stop: EarlyStop = True,
    lipschitz: Lipschitz = None, pnp: o.Pnp = "ippe_lm", landscape: Landscape = None,
    executor: o.Executor = "local", workers: o.Workers = 0, clock: o.Clock = "auto", wait: o.Wait = False,
    retry_failed: o.RetryFailed = False, address: o.Address = None, allow_unmeasured: o.AllowUnmeasured = False,
    csv: o.Csv = None, parquet: o.Parquet = None, report: o.Report = True,
    quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
    sequences: Sequences = None, monitor_residual: MonitorResidual = None, monitor_sigma: MonitorSigma = None,
    target: Target = "any",
    sustain: Sustain = 1, frames: Frames = None, rate: Rate = None, refine_zones: RefineZones = 0,
) -> None:
    """Find each image's worst case over a perturbation box: worst θ, worst error, verdict, survival, report."""
    from dataclasses import replace

    from vbl_robust.campaigns import Budget, audit_spec
    from vbl_robust.constants import TARGETS

    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    box_spec = parse_box(roll, contrast, perturb)
    if target not in TARGETS:
        fail(f"--target {target}: choose {' or '.join(TARGETS)}")
    check_executor(executor, address)
    frames, rate = _sequence_settings(sequences, sustain, frames, rate)
    with one_line(ValueError):
        budget = Budget(max_evals=max_evals or None, max_seconds=max_seconds, stop_at_breach=early_stop)
    method_list = parse_methods(methods)
    if landscape is None:  # on for images; for sequences a grid costs every frame per point: asked for only
        landscape = sequences is None
    counts = (21, 11)[: box_spec.box.dim] if landscape and box_spec.box.dim <= 2 else None
    spec = audit_spec(box_spec, methods=method_list, budget=budget, seed=seed, lipschitz=parse_lipschitz(lipschitz),
                      pnp=pnp, landscape=counts, sustain=None if sequences is None else sustain, target=target)
    method_opts = parse_method_options(method_option)
    spec = with_method_options(spec, method_opts)
    if monitor_residual is not None:
        with one_line(ValueError):
            spec = replace(spec, monitor_px=float(monitor_residual))
    if monitor_sigma is not None:
        with one_line(ValueError):
            spec = replace(spec, monitor_sigma_m=float(monitor_sigma))
            spec.check()
    spec, workers = run_settings(spec, clock, device, workers)
    check_exports(csv, parquet, out)
    det = detector_spec(model, trust_model, oracle, oracle_noise, design, engine, device, plugin=detector_plugin,
                        plugin_digest=plugin_digest)
    from vbl_robust.campaigns.work import detector_for  # built once per process: the run reuses it

    if monitor_sigma is not None and not getattr(detector_for(det), "gives_sigma", False):
        fail(f"--monitor-sigma {monitor_sigma:g}: the detector ({det.name}) gives no per-corner σ; the σ monitor "
             "needs a network with an uncertainty head (YOLO26-pose, see train --arch)")
    samples, source = _samples(sequences, lard, n, seed, width, height, frames, rate)
    config = {"command": "audit", "n": len(samples) if sequences is None else n, "seed": seed,
              "lard": str(lard) if lard else None, "roll": roll, "contrast": contrast, "methods": list(method_list),
              "max_evals": max_evals, "max_seconds": max_seconds, "early_stop": early_stop, "lipschitz": lipschitz,
              "pnp": pnp, "width": width, "height": height, **({"perturb": list(perturb)} if perturb else {}),
              **({} if sequences is None else {"sequences": sequences, "sustain": sustain, "frames": frames,
                                               "rate": rate}),
              **({"method_options": method_opts} if method_opts else {})}
    summary = run_with_progress(spec, samples, out, det, executor=executor, address=address, source=source,
                                config=config, quiet=quiet, workers=workers, wait=wait, retry_failed=retry_failed,
                                allow_unmeasured=allow_unmeasured)
    complete = finish(out, summary, csv=csv, parquet=parquet, report=report, quiet=quiet,
                      allow_unmeasured=allow_unmeasured)
    if refine_zones:
        from .zones import refine_audit

        refine_audit(out, samples, det, refine_zones, lipschitz=parse_lipschitz(lipschitz), quiet=quiet)
    if not complete:
        raise typer.Exit(1)


def _sequence_settings(sequences: str | None, sustain: int, frames: int | None, rate: float | None,
                       ) -> tuple[int, float]:
    """``--frames`` and ``--rate`` (defaults 20 frames, 10 Hz); they and ``--sustain`` apply to ``--sequences``
    only."""
    if sequences is None:
        for flag, value in (("--sustain", None if sustain == 1 else sustain), ("--frames", frames), ("--rate", rate)):
            if value is not None:
                fail(f"{flag} {value:g} applies to --sequences only")
    return frames or 20, 10.0 if rate is None else rate


def _samples(sequences: str | None, lard: Path | None, n: int | None, seed: int, width: int, height: int,
             frames: int, rate: float) -> tuple[list, dict]:
    """The audit's images, or its approach sequences (``--sequences``)."""
    if sequences is None:
        return load(n, seed, lard, width, height)
    if lard is not None:
        fail("--lard and --sequences: give a LARD V2 directory of sequences as --sequences DIR")
    return load_sequence_samples(sequences, frames, rate, seed, width, height)


# -- demo's own options -------------------------------------------------------------------------------------------
DemoOut = Annotated[Path, typer.Option("--out", help="Run directory.")]
DemoImages = Annotated[int, typer.Option("--n", "--images", min=1, max=MAX_IMAGES, help="Number of synthetic images.")]
DemoMaxEvals = Annotated[int, typer.Option("--max-evals", min=1, max=MAX_EVALS, help="Evaluations per image and "
                                           "method.")]
DemoLandscape = Annotated[bool, typer.Option("--landscape/--no-landscape", help="Dense 21 × 11 grid on the first "
                                             "image for the report's landscape figure.")]


def demo(
    out: DemoOut = Path("runs/demo"), n: DemoImages = 10, seed: o.Seed = 0, max_evals: DemoMaxEvals = 40,
    oracle: o.Oracle = False, engine: o.Engine = "auto", device: o.Device = "cpu", landscape: DemoLandscape = True,
    workers: o.Workers = 0, quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
) -> None:
    """A small audit on the defaults (10 synthetic images, georobust-av / random / APGD, roll ±15° and contrast
    [0.7, 1.4], early stop at a breach) with its HTML report — a few minutes on a laptop CPU."""
    import torch

    from vbl_robust.campaigns import Budget, audit_spec, roll_contrast_box

    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    if "OMP_NUM_THREADS" not in os.environ:
        torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    spec = audit_spec(roll_contrast_box(15.0, (0.7, 1.4)), budget=Budget(max_evals=max_evals), seed=seed,
                      landscape=(21, 11) if landscape else None)
    spec, workers = run_settings(spec, "auto", device, workers)
    det = detector_spec(None, False, oracle, DEMO_ORACLE_NOISE_PX, engine=engine, device=device,
                        noise_needs_oracle=False)
    samples, source = load(n, seed, None, 1024, 1024)
    config = {"command": "demo", "n": n, "seed": seed, "max_evals": max_evals, "landscape": landscape}
    summary = run_with_progress(spec, samples, out, det, executor="local", address=None, source=source,
                                config=config, quiet=quiet, workers=workers)
    if not finish(out, summary, csv=out / "jobs.csv", parquet=None, report=True, quiet=quiet):
        raise typer.Exit(1)
