"""Helpers shared by the CLI commands: one-line errors, verbosity, and the user's input read into the library's
objects — ranges, a perturbation box, search methods and their options, the detector (the shared options:
:mod:`.options`; running a campaign: :mod:`.run`)."""

from __future__ import annotations

import logging
import math
import os
import re
import signal
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from vbl_robust.consent import DetectorKind
from vbl_robust.perturb.registry import PERTURBATIONS, known
from vbl_robust.space import ParameterBox
from vbl_robust.specs.campaign import BoxSpec, box_label

from .config import get_current_context

if TYPE_CHECKING:  # torch behind it: imported where a detector is chosen, so that ``vbl-robust --help`` is instant
    from vbl_robust.detect.shipped import DetectorSpec

#: what the options before the command said (``vbl-robust -q audit …``)
_GLOBAL = {"quiet": False, "verbose": False}


def stop_on_sigterm() -> None:
    """Make SIGTERM (``kill PID``, a scheduler's or a session's stop) end the command as Ctrl-C does: a campaign
    records its run as interrupted with its wall time, its finished jobs stay, and the command exits with one line.
    A second SIGTERM kills at once (the default action is restored by the first)."""
    def _interrupt(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _interrupt)


def set_verbosity(*, quiet: bool = False, verbose: bool = False, before_command: bool = False) -> bool:
    """Apply ``-v`` (INFO logging) and ``-q`` given before the command (``before_command``: what they say for this
    invocation) or after it (added to that); returns whether to be quiet."""
    if before_command:
        _GLOBAL.update(quiet=quiet, verbose=verbose)
    _GLOBAL["quiet"] = _GLOBAL["quiet"] or quiet
    _GLOBAL["verbose"] = _GLOBAL["verbose"] or verbose
    logging.basicConfig(format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(logging.INFO if _GLOBAL["verbose"] else logging.WARNING)
    return _GLOBAL["quiet"]


#: Every character :meth:`str.splitlines` breaks a line at.
_LINE_BREAKS = re.compile("[\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")


def fail(message: str, code: int = 2) -> None:
    """Print a one-line error and exit (user mistakes never show a traceback). A line break inside ``message`` (an
    exception's text quoting bytes of a damaged file) is shown escaped: the refusal stays one line."""
    one = _LINE_BREAKS.sub(lambda m: repr(m.group())[1:-1], str(message))
    typer.secho(f"error: {one}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code)


def check_names(option: str, path: Path) -> None:
    """Refuse a path with a name longer than its file system allows (255 bytes on most), before any work: the
    run would stop at its first write."""
    limit = 255
    try:
        limit = os.pathconf(next((p for p in (path, *path.parents) if p.exists()), Path(".")), "PC_NAME_MAX")
    except (OSError, ValueError):
        pass
    long = next((part for part in path.parts if len(os.fsencode(part)) > limit), None)
    if long is not None:
        fail(f"{option} {path}: a name in it is {len(os.fsencode(long))} bytes long, over the file system's "
             f"{limit}")


def check_writable(option: str, path: Path) -> None:
    """Refuse, before any work, an output file the command could not write at its end: a directory, or a place
    where no file can be created — tried for real in the nearest existing folder (a file made and removed at once:
    a writable mode bit says nothing on /proc, a read-only mount or a full disk)."""
    if path.is_dir():
        fail(f"{option} {path}: is a directory")
    parent = next((p for p in (path.parent, *path.parent.parents) if p.exists()), Path("."))
    try:
        fd, probe = tempfile.mkstemp(dir=parent, prefix=".vbl-robust-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        fail(f"{option} {path}: cannot write there ({parent}: {exc.strerror or exc})")


@contextmanager
def one_line(*errors: type[Exception], prefix: str = "") -> Iterator[None]:
    """Inside: ``errors`` (default ``ValueError``, ``FileNotFoundError``: the library's refusals) end the command in
    one line, ``prefix`` before the message, exit 2."""
    caught = errors or (ValueError, FileNotFoundError)
    try:
        yield
    except caught as exc:
        fail(f"{prefix}{exc}")


def parse_range(text: str, *, name: str, symmetric: bool = False) -> tuple[float, float]:
    """Parse ``"15"`` (→ ±15 when ``symmetric``) or ``"0.7,1.4"`` into ``(lower, upper)``."""
    parts = [p.strip() for p in text.split(",")]
    if not all(parts):  # "5," or ",5" is a typo, not ±5
        raise typer.BadParameter(f"{name}: expected a number or 'lower,upper', got {text!r} (an empty value)")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise typer.BadParameter(f"{name}: expected a number or 'lower,upper', got {text!r}") from None
    if not all(math.isfinite(v) for v in vals):
        raise typer.BadParameter(f"{name}: expected finite numbers, got {text!r}")
    if len(vals) == 1 and symmetric:
        if vals[0] <= 0:  # "-5" would silently mean ±5
            raise typer.BadParameter(f"{name} {text}: a half-width must be > 0 (or give 'lower,upper')")
        return (-vals[0], vals[0])
    if len(vals) != 2:
        raise typer.BadParameter(f"{name}: expected 'lower,upper', got {text!r}")
    if not vals[0] < vals[1]:
        raise typer.BadParameter(f"{name} {text}: expected lower < upper")
    return (vals[0], vals[1])


def parse_lipschitz(text: str | None) -> float | tuple[float, ...] | None:
    """``--lipschitz``: one number, or one per parameter (checked against the box where the box is known)."""
    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))  # "5," (a stray comma) is no number either
    except ValueError:
        vals = ()
    if not vals or any(not math.isfinite(v) or v < 0 for v in vals):
        fail(f"--lipschitz {text}: expected a finite number >= 0, or one per parameter")
    return vals[0] if len(vals) == 1 else vals


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


def parse_box(roll: str, contrast: str | None, perturb: list[str] | None) -> BoxSpec:
    """The :class:`~vbl_robust.specs.campaign.BoxSpec` of ``--roll``, ``--contrast`` and ``--perturb`` (level: the
    roll half-width, 0 without roll), or one line naming the option at fault."""
    bounds: dict[str, tuple[float, float]] = {}
    extra = parse_perturb(perturb)
    if roll.strip().lower() != "none" and "roll_deg" not in extra:
        bounds["roll_deg"] = parse_range(roll, name="--roll", symmetric=True)
        lo, hi, spec = *bounds["roll_deg"], PERTURBATIONS["roll_deg"]
        if lo < spec.minimum or hi > spec.maximum:
            fail(f"--roll {roll}: roll_deg must lie within [{spec.minimum:g}, {spec.maximum:g}] degrees")
    if contrast is not None:
        if "contrast" in extra:
            fail("--contrast and --perturb contrast=...: give the contrast range once")
        bounds["contrast"] = parse_range(contrast, name="--contrast")
    bounds.update(extra)
    if not bounds:
        fail("give at least one of --roll, --contrast, --perturb")
    with one_line(ValueError):
        box = ParameterBox(bounds)
    level = max(abs(v) for v in bounds["roll_deg"]) if "roll_deg" in bounds else 0.0
    return BoxSpec(box, box_label(bounds), level)


def parse_methods(text: str) -> tuple[str, ...]:
    """``--methods a,b``: search methods, each known and given once."""
    from vbl_robust.search.api import METHODS  # scipy behind it: not for ``--help``

    methods = tuple(m.strip() for m in text.split(","))
    if methods != ("",) and not all(methods):  # "random," is a typo, not "random"
        raise typer.BadParameter(f"--methods {text}: an empty method name (a stray comma)")
    methods = tuple(m for m in methods if m)
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
    import yaml  # not for ``--help``

    from vbl_robust.search.api import METHODS, method_options  # scipy behind it: not for ``--help``

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
        except (yaml.YAMLError, ValueError):  # ValueError: an integer past Python's digit limit
            fail(f"--method-option {text!r}: value {raw!r} is not a number, boolean, string or list")
        if name in out.setdefault(method, {}):
            fail(f"--method-option {text!r}: {method}.{name} is given twice")
        out[method][name] = value
    return out


def with_method_options(spec: Any, options: dict[str, dict[str, Any]], strict: bool = True) -> Any:
    """``spec`` with the parsed ``--method-option`` values, or a one-line error."""
    if not options:
        return spec
    with one_line(ValueError, prefix="--method-option: "):
        return spec.with_method_options(options, strict=strict)


def detector_spec(model: Path | None, trust_model: bool, oracle: bool, oracle_noise: float,
                  design: str = "auto", engine: str = "torch", device: str = "cpu", *,
                  noise_needs_oracle: bool = True, plugin: str | None = None, plugin_digest: str | None = None,
                  ) -> DetectorSpec:
    """:meth:`DetectorSpec.from_choice <vbl_robust.detect.shipped.DetectorSpec.from_choice>` of the detector
    options, or one line; notes on standard error when the oracle stands in for the shipped model (and why) or
    when the shipped model has open accuracy goals."""
    # torch behind it: not for ``--help``
    from vbl_robust.detect.shipped import DetectorSpec, default_model_status

    # consent to run code (a .pt pickle, a plug-in) is the user's typing, never a value read from a --config file:
    # a plug-in named on the command line is consent to import it; one from a file needs --trust-model typed
    if trust_model and from_config("trust_model"):
        fail("--trust-model: give it on the command line; a --config file cannot consent to running a model's code")
    consent = trust_model or (plugin is not None and not from_config("detector_plugin"))
    if plugin is not None and not consent:
        fail(f"--detector-plugin {plugin} comes from a --config file: importing it runs its code; pass --trust-model "
             "on the command line if you trust it")
    with one_line():
        spec = DetectorSpec.from_choice(model, oracle=oracle, oracle_noise=oracle_noise, design=design, engine=engine,
                                        device=device, trust=trust_model if plugin is None else consent,
                                        noise_needs_oracle=noise_needs_oracle, plugin=plugin,
                                        plugin_digest=plugin_digest)
    if spec.kind == DetectorKind.DEFAULT:
        _note_open_goals(spec.shipped_name)
    elif spec.kind == DetectorKind.ORACLE and not oracle:
        noise = f", {oracle_noise:g} px fixed corner noise" if oracle_noise else ""
        typer.secho(f"note: {default_model_status()}; using the oracle detector (ground-truth corners{noise}). "
                    "Pass --model PATH for your model, or --model default to audit the shipped one anyway.",
                    fg=typer.colors.YELLOW, err=True)
    return spec


def from_config(param: str, ctx: Any = None) -> bool:
    """Whether the running command's option ``param`` took its value from a ``--config`` file (the context's default
    map) — data, not the user's typing. Compared by name: typer carries its own copy of click (and its
    ``ParameterSource``); ``ctx`` defaults to the running command's."""
    if ctx is None:
        ctx = get_current_context(silent=True)
    return ctx is not None and getattr(ctx.get_parameter_source(param), "name", None) == "DEFAULT_MAP"


def _note_open_goals(name: str = "default") -> None:
    """Tell the user which accuracy goals the shipped model ``name`` has not reached (also in the report)."""
    from vbl_robust.detect.shipped import default_model_caveats  # torch: not for ``--help``

    which = "" if name == "default" else f"{name} "
    for goal in default_model_caveats(name=name):
        typer.secho(f"note: the shipped {which}detector model has an open accuracy goal: {goal} (see its MODEL_CARD.md)",
                    fg=typer.colors.YELLOW, err=True)
