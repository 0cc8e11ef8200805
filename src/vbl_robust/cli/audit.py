"""``vbl-robust audit`` (the main job) and ``vbl-robust demo`` (a small audit on the defaults, with its report).

Also the helpers the campaign commands share: choosing the detector, running a campaign with a rich progress
bar, printing the summary, exporting and writing the report.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import typer

from vbl_robust.constants import MAX_EVALS, MAX_IMAGES
from vbl_robust.perturb.registry import PERTURBATIONS, known

from . import options as o
from .common import (
    fail,
    parse_lipschitz,
    parse_range,
    set_verbosity,
)

# -- shared by audit / demo / reproduce ---------------------------------------------------------------------------
#: Fixed corner noise of the oracle stand-in (``--oracle``, or no validated model installed): exact corners
#: make L(θ) flat in roll (< 1 cm), which shows nothing; 1 px is about what a good detector achieves.
DEMO_ORACLE_NOISE_PX = 1.0
#: Images of an audit when --n is not given (all rows of a smaller --lard dataset).
AUDIT_IMAGES = 20


def detector_spec(model: Path | None, trust_model: bool, oracle: bool, oracle_noise: float,
                  design: str = "auto", engine: str = "torch", device: str = "cpu", *,
                  noise_needs_oracle: bool = True) -> Any:
    """The detector the user asked for: --oracle, --model PATH, else the shipped model (oracle if not installed).

    ``design`` (``--detector``): ``auto`` (the shipped model's own design; a user's model as a single pass),
    ``single`` or ``twostage``. ``device`` (``--device``): ``auto``, ``cpu``, ``cuda[:N]``. A corner noise without
    ``oracle`` is refused (the user's ``--oracle-noise`` would be ignored) unless ``noise_needs_oracle`` is False
    (the demo's noise of its fallback oracle).
    """
    import dataclasses

    from vbl_robust.detect.shipped import (
        DESIGNS,
        SHIPPED_MODELS,
        DetectorSpec,
        default_model_path,
        default_model_status,
    )

    if design != "auto" and design not in DESIGNS:
        fail(f"--detector {design}: choose auto, {' or '.join(DESIGNS)}")
    if oracle and design != "auto":
        fail("--detector applies to a model, not to --oracle")
    if oracle and engine not in ("auto", "torch"):
        fail(f"--engine {engine} applies to a model, not to --oracle")
    if oracle and device != "cpu":
        fail(f"--device {device} applies to a model, not to --oracle (the oracle needs no device)")
    if oracle_noise and not oracle and noise_needs_oracle:
        fail(f"--oracle-noise {oracle_noise:g} applies to --oracle only")
    opts = {} if design == "auto" else {"design": design}
    if not oracle:
        from vbl_robust.detect.device import resolve_device
        from vbl_robust.detect.engines import resolve_engine

        try:
            dev = resolve_device(device)
        except ValueError as exc:
            fail(f"--device {device}: {exc}")
        try:
            resolved = resolve_engine(engine, dev)
        except ValueError as exc:
            fail(f"--engine {engine}: {exc}")
        if resolved != "torch":  # torch is every spec's default engine
            opts["engine"] = resolved
        if dev != "cpu":  # the CPU is every spec's default device
            opts["device"] = dev

    if oracle and model is not None:
        fail("--oracle and --model are exclusive")
    if oracle:
        return DetectorSpec.oracle(oracle_noise)
    if model is not None and str(model) in SHIPPED_MODELS:
        name = str(model)
        if name != "default" and default_model_path(name) is None:
            fail(f"--model {name}: {default_model_status(name)}")
        _note_open_goals(name)
        return DetectorSpec.shipped(name, opts)
    if model is not None:
        try:
            spec = DetectorSpec.from_path(model, trust=trust_model)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        return dataclasses.replace(spec, options=opts) if opts else spec
    spec, why = DetectorSpec.choose(oracle_noise_px=oracle_noise, options=opts)
    if not why:
        _note_open_goals()
        return spec
    noise = f", {oracle_noise:g} px fixed corner noise" if oracle_noise else ""
    typer.secho(f"note: {why}; using the oracle detector (ground-truth corners{noise}). "
                "Pass --model PATH for your model, or --model default to audit the shipped one anyway.",
                fg=typer.colors.YELLOW, err=True)
    return spec


def _note_open_goals(name: str = "default") -> None:
    """Tell the user which accuracy goals the shipped model ``name`` has not reached (also in the report)."""
    from vbl_robust.detect.shipped import default_model_caveats

    which = "" if name == "default" else f"{name} "
    for goal in default_model_caveats(name=name):
        typer.secho(f"note: the shipped {which}detector model has an open accuracy goal: {goal} (see its MODEL_CARD.md)",
                    fg=typer.colors.YELLOW, err=True)



def parse_perturb(items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``--perturb NAME=LO,HI`` (repeatable; a bare ``NAME`` takes the family's plausible default range) →
    ``{name: (lo, hi)}`` in the order given; a one-line error naming the flag and the value on bad input."""
    out: dict[str, tuple[float, float]] = {}
    for item in items or ():
        name, sep, text = (part.strip() for part in item.partition("="))
        if name not in PERTURBATIONS:
            fail(f"--perturb {item}: unknown perturbation {name!r}; known perturbations: {known()}")
        if name in out:
            fail(f"--perturb {item}: {name} is given more than once")
        spec = PERTURBATIONS[name]
        if not sep:
            out[name] = spec.default
            continue
        try:
            lo, hi = (float(v) for v in text.split(","))
        except ValueError:
            fail(f"--perturb {item}: expected {name}=LOWER,UPPER (two numbers), got {text!r}")
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            fail(f"--perturb {item}: expected finite bounds with LOWER < UPPER, got {text!r}")
        if lo < spec.minimum or hi > spec.maximum:
            fail(f"--perturb {item}: {name} must lie within [{spec.minimum:g}, {spec.maximum:g}] ({spec.description})")
        out[name] = (lo, hi)
    return out


def parse_box(roll: str, contrast: str | None, perturb: list[str] | None) -> Any:
    """The :class:`~vbl_robust.campaigns.spec.BoxSpec` of ``--roll``, ``--contrast`` and ``--perturb`` (level: the
    roll half-width, 0 without roll), or one line naming the option at fault."""
    from vbl_robust.campaigns import BoxSpec
    from vbl_robust.campaigns.spec import box_label
    from vbl_robust.space import ParameterBox

    bounds: dict[str, tuple[float, float]] = {}
    extra = parse_perturb(perturb)
    if roll.strip().lower() != "none" and "roll_deg" not in extra:
        bounds["roll_deg"] = parse_range(roll, name="--roll", symmetric=True)
    if contrast is not None:
        if "contrast" in extra:
            fail("--contrast and --perturb contrast=...: give the contrast range once")
        bounds["contrast"] = parse_range(contrast, name="--contrast")
    bounds.update(extra)
    if not bounds:
        fail("give at least one of --roll, --contrast, --perturb")
    try:
        box = ParameterBox(bounds)
    except ValueError as exc:
        fail(str(exc))
    level = max(abs(v) for v in bounds["roll_deg"]) if "roll_deg" in bounds else 0.0
    return BoxSpec(box, box_label(bounds), level)


def parse_methods(text: str) -> tuple[str, ...]:
    from vbl_robust.search import METHODS

    methods = tuple(m.strip() for m in text.split(",") if m.strip())
    bad = [m for m in methods if m not in METHODS]
    if not methods or bad:
        raise typer.BadParameter(f"--methods: unknown method(s) {bad or text!r}; methods are {', '.join(METHODS)}")
    twice = sorted({m for m in methods if methods.count(m) > 1})
    if twice:
        raise typer.BadParameter(f"--methods {text}: {', '.join(twice)} given more than once")
    return methods


def parse_method_options(values: list[str] | None) -> dict[str, dict[str, Any]]:
    """``--method-option METHOD.OPTION=VALUE`` (repeatable) → ``{method: {option: value}}``; a one-line error
    naming the flag and the value for an unknown method or option or an unreadable value."""
    import yaml

    from vbl_robust.search import METHODS, method_options

    out: dict[str, dict[str, Any]] = {}
    for text in values or []:
        key, sep, raw = text.partition("=")
        method, dot, name = key.strip().rpartition(".")
        if not sep or not dot or not method or not name or not raw.strip():
            fail(f"--method-option {text!r}: expected METHOD.OPTION=VALUE, e.g. georobust-a.min_ratio=9")
        if method not in METHODS:
            fail(f"--method-option {text!r}: unknown method {method!r}; methods are {', '.join(METHODS)}")
        allowed = method_options(method)
        if name not in allowed:
            fail(f"--method-option {text!r}: method {method!r} has no option {name!r}; options are "
                 f"{', '.join(allowed)}")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError:
            fail(f"--method-option {text!r}: value {raw!r} is not a number, boolean, string or list")
        if name in out.setdefault(method, {}):
            fail(f"--method-option {text!r}: {method}.{name} is given twice")
        out[method][name] = value
    return out


def with_method_options(spec: Any, options: dict[str, dict[str, Any]], strict: bool = True) -> Any:
    """``spec`` with the parsed ``--method-option`` values, or a one-line error."""
    if not options:
        return spec
    try:
        return spec.with_method_options(options, strict=strict)
    except ValueError as exc:
        fail(f"--method-option: {exc}")


def run_settings(spec: Any, clock: str, device: str, workers: int) -> tuple[Any, int]:
    """``spec`` on the clock the user chose (``auto``: process time on a CPU, wall time on a GPU) and the worker
    count (0: :func:`~vbl_robust.campaigns.runner.default_workers`); a bad value fails with one line."""
    from dataclasses import replace

    from vbl_robust.campaigns.runner import default_workers
    from vbl_robust.search import CLOCKS

    if clock == "auto":
        clock = "process" if device == "cpu" else "wall"
    if clock not in CLOCKS:
        fail(f"--clock must be auto, {' or '.join(sorted(CLOCKS))}, got {clock!r}")
    if workers < 0:
        fail(f"--workers must be >= 0 (0 = one per core), got {workers}")
    try:
        return replace(spec, clock=clock), workers or default_workers()
    except ValueError as exc:
        fail(str(exc))
    raise AssertionError("unreachable")  # pragma: no cover


def run_with_progress(spec: Any, samples: list, out: Path, detector: Any, *, executor: str, address: str | None,
                      source: dict, config: dict, quiet: bool = False, workers: int = 1, wait: bool = False,
                      retry_failed: bool = False) -> Any:
    """Run ``spec`` into ``out/results.sqlite`` with a rich progress bar (``workers`` processes for the local
    executor; ``wait``: wait for another run writing the same store instead of refusing); returns the run
    summary."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from vbl_robust.campaigns import ResultStore, run_campaign

    try:
        spec.check()  # before anything is created or run
        spec.check_samples(samples)
    except ValueError as exc:
        fail(str(exc))
    try:
        out.mkdir(parents=True, exist_ok=True)
        ResultStore(out / "results.sqlite").close()  # a store that cannot be opened fails here, in one line
    except (ValueError, OSError) as exc:
        fail(f"--out {out}: {exc}")
    columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("jobs"),
               TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), TextColumn("{task.fields[status]}"))
    with ResultStore(out / "results.sqlite") as store, Progress(*columns, disable=quiet, transient=False) as bar:
        task = bar.add_task(spec.name, total=None, status="")

        def on_progress(p: Any) -> None:
            bar.update(task, total=p.total, completed=p.done,
                       status=f"breaches {p.breaches}" + (f", failed {p.failed}" if p.failed else "")
                       + (f" ({p.skipped} resumed)" if p.skipped else ""))

        try:
            summary = run_campaign(spec, samples, store, detector=detector, executor=executor, workers=workers,
                                   address=address, progress=on_progress, dataset_source=source, config=config,
                                   wait=wait, retry_failed=retry_failed)
        except (ValueError, FileNotFoundError) as exc:
            fail(str(exc))
        except KeyboardInterrupt:
            bar.stop()
            fail(f"interrupted; finished jobs are saved in {out / 'results.sqlite'}: rerun the same command to resume",
                 code=130)
    return summary


def check_exports(csv: Path | None, parquet: Path | None, out: Path | None = None) -> None:
    """Refuse, before a run, an export the run could not write at its end: a ``--csv`` / ``--parquet`` name with
    another suffix, a directory, or a place that cannot be created or written; also an ``--out`` that is a file."""
    import os

    if out is not None and out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file, not a run directory")
    for option, path, suffix in (("--csv", csv, ".csv"), ("--parquet", parquet, ".parquet")):
        if path is None:
            continue
        if path.suffix.lower() != suffix:
            fail(f"{option} {path}: the file name must end in {suffix}")
        if path.is_dir():
            fail(f"{option} {path}: is a directory")
        parent = next((p for p in (path.parent, *path.parent.parents) if p.exists()), Path("."))
        if not parent.is_dir() or not os.access(parent, os.W_OK):
            fail(f"{option} {path}: cannot write there ({parent} is not a writable directory)")


def finish(out: Path, summary: Any, *, csv: Path | None, parquet: Path | None, report: bool, quiet: bool = False) -> bool:
    """Print the summary table, export, and write the HTML report; False when the run is incomplete (its caller
    ends with exit code 1 once it has done what else it can: a run that did not finish never exits 0)."""
    from rich.console import Console
    from rich.table import Table

    from vbl_robust.campaigns import ResultStore, export, summarize
    from vbl_robust.campaigns.metrics import main_rows
    from vbl_robust.campaigns.spec import CampaignSpec

    with ResultStore.open_existing(out) as store:
        spec = CampaignSpec.from_dict(store.campaign()["spec"])
        rows = main_rows(store, spec, with_trace=False)  # runs that read smaller budgets off their trace: per budget
        for path in (csv, parquet):
            if path is not None:
                try:
                    export(store, path)
                except ValueError as exc:
                    fail(str(exc))
                typer.echo(f"exported {path}")
    if rows and not quiet:
        lines = summarize(rows, spec.eps_safe_m)
        cols = ["method"] + [c for c in ("box_label", "budget_label") if len({getattr(ln, c) for ln in lines}) > 1]
        fixed = ", ".join(str(getattr(lines[0], c)) for c in ("box_label", "budget_label") if c not in cols)
        table = Table(title=f"{spec.name}: survival (worst error ≤ {spec.eps_safe_m:g} m)" + (f" — {fixed}" if fixed else ""))
        heads = {"method": "method", "box_label": "box", "budget_label": "budget"}
        for c in cols:  # a method's name is never cut (georobust and georobust-av must stay apart)
            table.add_column(heads[c], no_wrap=c == "method", min_width=max(len(str(ln.method)) for ln in lines)
                             if c == "method" else None)
        empty = any(line.n_empty for line in lines)  # survivors never searched (no evaluation in a time budget)
        heads = ["n", "survival % [95 % CI]", *(["no eval in time"] if empty else []), "median (m)", "breaches",
                 "failed"]
        cells = []
        for line in lines:
            fe, med = line.failed_evals, line.median_worst_m
            kinds = "?" if line.misleading is None else f"{line.misleading} / {line.flagged}"
            cells.append([str(line.n), line.survival_rate.text(1, percent=False),
                          *([str(line.n_empty)] if empty else []), "–" if math.isnan(med) else f"{med:.1f}",
                          f"{line.breaches} ({kinds})", f"{line.failed} / {'–' if fe is None else fe}"])
        for j, col in enumerate(heads):  # values are never cut: a column is at least as wide as its widest value
            table.add_column(col, justify="right", min_width=max(len(c[j]) for c in cells))
        for line, row in zip(lines, cells, strict=True):
            table.add_row(*(str(getattr(line, c)) for c in cols), *row)
        Console().print(table)
        typer.echo(f"n: {spec.unit}s; median: of the worst errors found; failed: jobs / evaluations; breaches: all "
                   "(m / f): m misleading — a confident pose off by more than ε_safe; f flagged only — every "
                   "breach a failure the system sees (no detection, low confidence, PnP failed …)")
        if empty:
            typer.echo("no eval in time: searches that completed no evaluation within their time budget; they "
                       "found nothing and count as survivors")
    status = f"{summary.done} new jobs, {summary.skipped} already done, {summary.failed} failed, {summary.seconds:.0f} s"
    typer.echo(f"{spec.name}: {status}; results in {out / 'results.sqlite'}")
    if summary.status != "finished":
        typer.secho(f"run {summary.status}: rerun the same command to resume", fg=typer.colors.YELLOW, err=True)
    if report:
        from vbl_robust.report import build_report

        typer.echo(f"report: {build_report(out)}")
    if summary.done and summary.failed == summary.done and summary.status == "finished":
        typer.secho(f"every job failed ({summary.failed}): nothing was measured — see the reasons in the report",
                    fg=typer.colors.RED, err=True)
        return False
    return summary.status == "finished"


def load_sequence_samples(source: str, frames: int, rate: float, seed: int, width: int, height: int,
                          ) -> tuple[list, dict]:
    """The approach sequences of ``--sequences`` (:func:`vbl_robust.campaigns.load_sequences`), or one line."""
    from vbl_robust.campaigns import load_sequences

    try:
        return load_sequences(source, frames=frames, rate_hz=rate, seed=seed, width=width, height=height)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        fail(str(exc))
    raise AssertionError("unreachable")  # pragma: no cover


def load(n: int | None, seed: int, lard: Path | None, width: int, height: int, *,
         default: int = AUDIT_IMAGES) -> tuple[list, dict]:
    """``n`` samples (``None``: ``default``, or all rows of a smaller ``lard`` dataset), or one line."""
    from vbl_robust.campaigns import load_samples

    try:
        return load_samples(default if n is None else n, seed, lard=lard, width=width, height=height,
                            at_most=n is None)
    except (ValueError, FileNotFoundError) as exc:
        fail(str(exc))
    raise AssertionError("unreachable")  # pragma: no cover


# -- commands -------------------------------------------------------------------------------------------------
def register(app: typer.Typer) -> None:
    from vbl_robust.campaigns.experiments import AUDIT_METHODS

    @app.command()
    def audit(
        out: Path = typer.Option(Path("runs/audit"), "--out", help="Run directory (results.sqlite, report.html)."),
        n: int | None = typer.Option(None, "--n", "--images", min=1, max=MAX_IMAGES, show_default=False,
                                     help=f"Number of images (default {AUDIT_IMAGES}, or all rows of a smaller --lard "
                                          "dataset)."),
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
        contrast: str | None = typer.Option(None, "--contrast", help="Contrast factor range 'lo,hi' (e.g. 0.7,1.4)."),
        perturb: list[str] | None = typer.Option(None, "--perturb", help="Another perturbation family and its range, "
                                                 "NAME=LO,HI (repeatable; a bare NAME takes its plausible default "
                                                 f"range): {known()} (roll_deg here replaces --roll; contrast "
                                                 "here or in --contrast, not both)."),
        methods: str = typer.Option(",".join(AUDIT_METHODS), "--methods", help="Comma-separated search methods."),
        method_option: list[str] | None = o.METHOD_OPTION,
        max_evals: int | None = typer.Option(200, "--max-evals", min=0, max=MAX_EVALS, help="Evaluations per image and method (0 = no "
                                                 "evaluation cap: then give --max-seconds)."),
        max_seconds: float | None = typer.Option(None, "--max-seconds", min=0.0, help="Seconds per image and method."),
        early_stop: bool = typer.Option(True, "--early-stop/--no-early-stop", help="Stop an image's search at its "
                                        "first breach (answers 'is there a breach?')."),
        lipschitz: str | None = typer.Option(None, "--lipschitz", help="Lipschitz constant of the error (m per unit, "
                                             "one number or one per parameter): enables 'certified' verdicts."),
        pnp: str = typer.Option("ippe_lm", "--pnp", help="PnP solver: ippe_lm, iterative, sqpnp, ippe."),
        landscape: bool | None = typer.Option(None, "--landscape/--no-landscape", help="Dense grid on the first image "
                                              "for the report's landscape figure (default: on; with --sequences off, "
                                              "as each grid point costs every frame of the first sequence)."),
        executor: str = o.EXECUTOR,
        workers: int = o.WORKERS,
        clock: str = o.CLOCK,
        wait: bool = o.WAIT,
        retry_failed: bool = o.RETRY_FAILED,
        address: str | None = o.ADDRESS,
        csv: Path | None = o.CSV,
        parquet: Path | None = o.PARQUET,
        report: bool = o.REPORT,
        quiet: bool = o.QUIET,
        verbose: bool = o.VERBOSE,
        config: Path | None = o.CONFIG,
        sequences: str | None = typer.Option(None, "--sequences", help="Audit approach sequences instead of images: "
                                             "a number N (generated) or a LARD V2 directory grouped into sequences; "
                                             "one θ is held over each sequence (see --sustain)."),
        monitor_residual: float | None = typer.Option(None, "--monitor-residual", help="A runtime monitor: a pose "
                                                      "whose PnP reprojection residual (RMS, image pixels) is above "
                                                      "this is a flagged failure, not a pose (measure what it flags "
                                                      "and rejects: BENCHMARKS, monitors)."),
        target: str = typer.Option("any", "--target", help="What the searches look for: any (every breach; a "
                                   "flagged failure — no detection, low confidence, PnP failed — counts 5000 m, "
                                   "as in the paper) or misleading (a flagged failure counts 0 m, as safe: every "
                                   "method hunts the worst confident pose, the hazardously misleading error)."),
        sustain: int = typer.Option(1, "--sustain", min=1, help="With --sequences: frames the error must hold "
                                    "(the worst error sustained over K consecutive frames)."),
        frames: int | None = typer.Option(None, "--frames", min=1, help="With --sequences N: frames per sequence "
                                          "(default 20)."),
        rate: float | None = typer.Option(None, "--rate", help="With --sequences: frame rate in Hz (generated "
                                          "sequences; LARD data without times; default 10)."),
        refine_zones: int = typer.Option(0, "--refine-zones", min=0, help="After the search: spend this many more "
                                         "evaluations per main DIRECT-family/grid job inside its undecided zones "
                                         "(GeoRobust per zone, largest first) and report how the breached / "
                                         "undecided / ruled-out fractions changed (zones_refined.json; under "
                                         "--lipschitz, else the search's own estimate)."),
    ) -> None:
        """Find each image's worst case over a perturbation box: worst θ, worst error, verdict, survival, report."""
        from vbl_robust.campaigns import Budget, audit_spec

        quiet = set_verbosity(quiet=quiet, verbose=verbose)

        box_spec = parse_box(roll, contrast, perturb)
        from vbl_robust.constants import TARGETS

        if target not in TARGETS:
            fail(f"--target {target}: choose {' or '.join(TARGETS)}")
        from vbl_robust.campaigns.runner import check_executor

        try:
            check_executor(executor, address)
        except ValueError as exc:
            fail(str(exc))
        if sequences is None:
            for flag, value in (("--sustain", None if sustain == 1 else sustain), ("--frames", frames),
                                ("--rate", rate)):
                if value is not None:
                    fail(f"{flag} {value:g} applies to --sequences only")
        frames, rate = frames or 20, 10.0 if rate is None else rate
        box = box_spec.box
        try:
            budget = Budget(max_evals=max_evals or None, max_seconds=max_seconds, stop_at_breach=early_stop)
        except ValueError as exc:
            fail(str(exc))
        method_list = parse_methods(methods)
        if landscape is None:  # on for images; for sequences a grid costs every frame per point: asked for only
            landscape = sequences is None
        counts = (21, 11)[: box.dim] if landscape and box.dim <= 2 else None
        spec = audit_spec(box_spec, methods=method_list, budget=budget, seed=seed,
                          lipschitz=parse_lipschitz(lipschitz), pnp=pnp, landscape=counts,
                          sustain=None if sequences is None else sustain, target=target)
        method_opts = parse_method_options(method_option)
        spec = with_method_options(spec, method_opts)
        if monitor_residual is not None:
            from dataclasses import replace

            try:
                spec = replace(spec, monitor_px=float(monitor_residual))
            except ValueError as exc:
                fail(str(exc))
        spec, workers = run_settings(spec, clock, device, workers)
        check_exports(csv, parquet, out)
        det = detector_spec(model, trust_model, oracle, oracle_noise, design, engine, device)
        if sequences is not None:
            if lard is not None:
                fail("--lard and --sequences: give a LARD V2 directory of sequences as --sequences DIR")
            samples, source = load_sequence_samples(sequences, frames, rate, seed, width, height)
        else:
            samples, source = load(n, seed, lard, width, height)
        config = {"command": "audit", "n": len(samples) if sequences is None else n, "seed": seed, "lard": str(lard) if lard else None, "roll": roll,
                  "contrast": contrast, "methods": list(method_list), "max_evals": max_evals, "max_seconds": max_seconds,
                  "early_stop": early_stop, "lipschitz": lipschitz, "pnp": pnp, "width": width, "height": height}
        if perturb:
            config["perturb"] = list(perturb)
        if sequences is not None:
            config.update(sequences=sequences, sustain=sustain, frames=frames, rate=rate)
        if method_opts:
            config["method_options"] = method_opts
        summary = run_with_progress(spec, samples, out, det, executor=executor, address=address, source=source,
                                    config=config, quiet=quiet, workers=workers, wait=wait,
                                    retry_failed=retry_failed)
        complete = finish(out, summary, csv=csv, parquet=parquet, report=report, quiet=quiet)
        if refine_zones:
            from .zones import refine_audit

            refine_audit(out, samples, det, refine_zones, lipschitz=parse_lipschitz(lipschitz), quiet=quiet)
        if not complete:
            raise typer.Exit(1)

    @app.command()
    def demo(
        out: Path = typer.Option(Path("runs/demo"), "--out", help="Run directory."),
        n: int = typer.Option(10, "--n", "--images", min=1, max=MAX_IMAGES, help="Number of synthetic images."),
        seed: int = o.SEED,
        max_evals: int = typer.Option(40, "--max-evals", min=1, max=MAX_EVALS, help="Evaluations per image and method."),
        oracle: bool = o.ORACLE,
        engine: str = o.ENGINE,
        device: str = o.DEVICE,
        landscape: bool = typer.Option(True, "--landscape/--no-landscape", help="Dense 21 × 11 grid on the first "
                                       "image for the report's landscape figure."),
        workers: int = o.WORKERS,
        quiet: bool = o.QUIET,
        verbose: bool = o.VERBOSE,
        config: Path | None = o.CONFIG,
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
