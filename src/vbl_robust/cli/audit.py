"""``vbl-robust audit`` (the main job) and ``vbl-robust demo`` (a small audit on the defaults, with its report).

From an option to the objective: the options become request objects (:mod:`.requests`: the box, the detector, the
images, how the run runs) and a :class:`~vbl_robust.specs.campaign.CampaignSpec`
(:func:`vbl_robust.campaigns.audit.audit_spec`: methods, budget, target, monitors); :meth:`RunRequest.run
<.requests.RunRequest.run>` runs it (:func:`vbl_robust.campaigns.runner.run_campaign`), and each job's objective
is built from the spec's settings, the sample and the detector by
:func:`vbl_robust.campaigns.work.build_objective` (:class:`vbl_robust.pipeline.Objective`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from vbl_robust.campaigns.audit import AUDIT_METHODS, audit_spec
from vbl_robust.constants import TARGETS
from vbl_robust.specs.budget import Budget
from vbl_robust.specs.campaign import roll_contrast_box

from . import options as o
from .common import (
    fail,
    one_line,
    parse_lipschitz,
    parse_method_options,
    parse_methods,
    set_verbosity,
    with_method_options,
)
from .config import parameters, run_config
from .requests import BoxRequest, DetectorRequest, ExportRequest, ImagesRequest, RunRequest
from .run import load_sequence_samples
from .zones import refine_audit

if TYPE_CHECKING:
    from vbl_robust.detect.shipped import DetectorSpec

#: Fixed corner noise of the demo's oracle (``--oracle``, or no validated model installed): exact corners make
#: L(θ) flat in roll (< 1 cm), which shows nothing; 1 px is about what a good detector achieves.
DEMO_ORACLE_NOISE_PX = 1.0

# -- audit's own options ------------------------------------------------------------------------------------------
MaxSeconds = Annotated[float | None, typer.Option("--max-seconds", min=0.0, help="Seconds per image and method.")]
EarlyStop = Annotated[bool, typer.Option("--early-stop/--no-early-stop", help="Stop an image's search at its first "
                                         "breach (answers 'is there a breach?').")]
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
    roll: o.Roll = "15", contrast: o.Contrast = None, perturb: o.Perturb = None,
    methods: o.Methods = ",".join(AUDIT_METHODS), method_option: o.MethodOption = None,
    max_evals: o.MaxEvals = 200, max_seconds: MaxSeconds = None, early_stop: EarlyStop = True,
    lipschitz: o.Lipschitz = None, pnp: o.Pnp = "ippe_lm", landscape: o.Landscape = None,
    executor: o.Executor = "local", workers: o.Workers = 0, clock: o.Clock = "auto", wait: o.Wait = False,
    retry_failed: o.RetryFailed = False, address: o.Address = None, allow_unmeasured: o.AllowUnmeasured = False,
    csv: o.Csv = None, parquet: o.Parquet = None, report: o.Report = True,
    quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
    sequences: Sequences = None, monitor_residual: MonitorResidual = None, monitor_sigma: MonitorSigma = None,
    target: Target = "any",
    sustain: Sustain = 1, frames: o.Frames = None, rate: o.Rate = None, refine_zones: RefineZones = 0,
) -> None:
    """Find each image's worst case over a perturbation box: worst θ, worst error, verdict, survival, report."""
    params = parameters()
    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    box_spec = BoxRequest.of(params).spec()
    if target not in TARGETS:
        fail(f"--target {target}: choose {' or '.join(TARGETS)}")
    run = RunRequest.of(params)
    run.check()
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
            spec = spec.with_settings(monitor_px=float(monitor_residual))
    if monitor_sigma is not None:
        with one_line(ValueError):
            spec = spec.with_settings(monitor_sigma_m=float(monitor_sigma))
            spec.check()
    spec, workers = run.settings(spec, device)
    exports = ExportRequest.of(params)
    exports.check(out)
    det = DetectorRequest.of(params).spec()
    if monitor_sigma is not None:
        _check_sigma(det, monitor_sigma)
    samples, source = _samples(sequences, ImagesRequest.of(params), frames, rate)
    config = run_config("audit", n=len(samples) if sequences is None else n, methods=list(method_list),
                        **({} if sequences is None else {"frames": frames, "rate": rate}),
                        **({"method_options": method_opts} if method_opts else {}))
    summary = run.run(spec, samples, out, det, source=source, config=config, quiet=quiet, workers=workers)
    complete = exports.finish(out, summary, quiet=quiet, allow_unmeasured=allow_unmeasured)
    if refine_zones:
        refine_audit(out, samples, det, refine_zones, lipschitz=parse_lipschitz(lipschitz), quiet=quiet)
    if not complete:
        raise typer.Exit(1)


def _check_sigma(det: DetectorSpec, monitor_sigma: float) -> None:
    """``--monitor-sigma`` needs a detector that gives each corner's σ (built here once: the run reuses it)."""
    from vbl_robust.campaigns.work import detector_for  # torch: not for ``--help``

    if not getattr(detector_for(det), "gives_sigma", False):
        fail(f"--monitor-sigma {monitor_sigma:g}: the detector ({det.name}) gives no per-corner σ; the σ monitor "
             "needs a network with an uncertainty head (YOLO26-pose, see train --arch)")


def _sequence_settings(sequences: str | None, sustain: int, frames: int | None, rate: float | None,
                       ) -> tuple[int, float]:
    """``--frames`` and ``--rate`` (defaults 20 frames, 10 Hz); they and ``--sustain`` apply to ``--sequences``
    only."""
    if sequences is None:
        for flag, value in (("--sustain", None if sustain == 1 else sustain), ("--frames", frames), ("--rate", rate)):
            if value is not None:
                fail(f"{flag} {value:g} applies to --sequences only")
    return frames or 20, 10.0 if rate is None else rate


def _samples(sequences: str | None, images: ImagesRequest, frames: int, rate: float) -> tuple[list, dict]:
    """The audit's images, or its approach sequences (``--sequences``)."""
    if sequences is None:
        return images.load()
    if images.lard is not None:
        fail("--lard and --sequences: give a LARD V2 directory of sequences as --sequences DIR")
    return load_sequence_samples(sequences, frames, rate, images.seed, images.width, images.height)


# -- demo's own options -------------------------------------------------------------------------------------------
DemoOut = o.variant(o.Out, help="Run directory.")
DemoImages = o.variant(o.Images, int, show_default=True, help="Number of synthetic images.")
DemoMaxEvals = o.variant(o.MaxEvals, int, min=1, help="Evaluations per image and method.")
DemoLandscape = o.variant(o.Landscape, bool, help="Dense 21 × 11 grid on the first image for the report's landscape "
                          "figure.")


def demo(
    out: DemoOut = Path("runs/demo"), n: DemoImages = 10, seed: o.Seed = 0, max_evals: DemoMaxEvals = 40,
    oracle: o.Oracle = False, engine: o.Engine = "auto", device: o.Device = "cpu", landscape: DemoLandscape = True,
    workers: o.Workers = 0, quiet: o.Quiet = False, verbose: o.Verbose = False, config: o.Config = None,
) -> None:
    """A small audit on the defaults (10 synthetic images, georobust-av / random / APGD, roll ±15° and contrast
    [0.7, 1.4], early stop at a breach) with its HTML report — a few minutes on a laptop CPU."""
    import torch  # not for ``--help``

    params = parameters()
    quiet = set_verbosity(quiet=quiet, verbose=verbose)
    if "OMP_NUM_THREADS" not in os.environ:
        torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    spec = audit_spec(roll_contrast_box(15.0, (0.7, 1.4)), budget=Budget(max_evals=max_evals), seed=seed,
                      landscape=(21, 11) if landscape else None)
    run = RunRequest.of(params)
    spec, workers = run.settings(spec, device)
    det = DetectorRequest.of(params, oracle_noise=DEMO_ORACLE_NOISE_PX).spec(noise_needs_oracle=False)
    samples, source = ImagesRequest.of(params).load()
    summary = run.run(spec, samples, out, det, source=source, config=run_config("demo"), quiet=quiet, workers=workers)
    if not ExportRequest(csv=out / "jobs.csv").finish(out, summary, quiet=quiet, allow_unmeasured=False):
        raise typer.Exit(1)
