"""The shipped default detector and how every detector of a run is named and built (:class:`DetectorSpec`).

The shipped model is ``vbl_robust/models/runway_yolov8n_pose.pt`` with ``default.json`` beside it: its design
(``"twostage"`` or ``"single"``), input size, version, and whether it passed its validation gates
(``"validated": true`` — detection ≥ 97 % and nominal survival ≥ 90 % on the held-out protocol of
``benchmarks/bench_detector.py``; below them a robustness figure mostly measures the detector's nominal failures)
and its ``"open_goals"``, printed by every run and shown in the report. See ``models/MODEL_CARD.md``. Other
models ship beside it under their own names (:data:`SHIPPED_MODELS`, the same two files in a directory of their
own: ``--model hardened``, ``DetectorSpec.shipped("hardened")``).

A :class:`DetectorSpec` names a detector by *how to build it* (kind + path), not by an object, so the same
spec rebuilds the detector once per process — in the local runner and in every Ray worker — and its identity
(kind, file SHA-256) goes into each job's key: results of two different models never mix in one store.
"""

from __future__ import annotations

import importlib
import json
import logging
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from vbl_robust.consent import CODE_KINDS, DETECTOR_KINDS, DetectorKind, refuse_without_consent
from vbl_robust.digest import digest, file_sha256

from .pose import PoseDetector

logger = logging.getLogger(__name__)

__all__ = ["DEFAULT_MODEL", "DESIGNS", "MODELS_DIR", "SHIPPED_MODELS", "DetectorSpec", "default_detector",
           "default_model_caveats", "default_model_info", "default_model_path", "default_model_status",
           "shipped_model_dir", "with_design"]

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
DEFAULT_MODEL = MODELS_DIR / "runway_yolov8n_pose.pt"
#: The models shipped with the package, by the name ``--model NAME`` takes: each a directory holding its weights
#: (``runway_yolov8n_pose.pt``) and ``default.json`` (how the model runs by default: design, input size; its
#: version, validation and open goals; ``"weights"`` names another weights file, ``"first"`` another shipped model
#: whose network is pass 1 of a two-stage design). ``default`` is what every run uses unless told otherwise;
#: ``hardened`` (``vbl-robust harden``) ships beside it and never replaces it, so every published result keeps its
#: model; ``yolo26`` is v9's pass 1 with a YOLO26-pose crop network as pass 2 that says how sure it is of each
#: corner (per-corner σ: ``--monitor-sigma``).
SHIPPED_MODELS = {"default": "", "hardened": "hardened", "yolo26": "yolo26"}  # name -> its directory under MODELS_DIR
#: Designs of a pose-model detector: one pass on the letterboxed image, or a pass on it and one on a crop.
DESIGNS = ("single", "twostage")


#: options of a two-stage detector's crop window (``TwoStageDetector(margin=..., min_side=...)``)
CROP_WINDOW_KEYS = ("margin", "min_side")


# -- the shipped models -----------------------------------------------------------------------------------------
def shipped_model_dir(name: str) -> Path:
    """The directory of the shipped model ``name`` (:data:`SHIPPED_MODELS`; ``ValueError`` for another name)."""
    if name not in SHIPPED_MODELS:
        raise ValueError(f"unknown shipped model {name!r}; shipped models: {', '.join(SHIPPED_MODELS)}")
    return MODELS_DIR / SHIPPED_MODELS[name]


def default_model_path(name: str = "default") -> Path | None:
    """The weights file of the shipped model ``name`` (:data:`SHIPPED_MODELS`) if it is installed, else None: the
    file its ``default.json`` names (``"weights"``), else ``runway_yolov8n_pose.pt``."""
    folder = shipped_model_dir(name)
    weights = DEFAULT_MODEL.name
    if name != "default":
        try:
            weights = str(json.loads((folder / "default.json").read_text()).get("weights") or weights)
        except (OSError, ValueError, AttributeError):
            pass
    f = folder / Path(weights).name  # a name inside the model's directory, never a path out of it
    return f if f.is_file() else None


def default_model_info(name: str = "default") -> dict[str, Any]:
    """The shipped model's ``default.json`` (design, input size, version, validation), ``{}`` if unreadable."""
    if default_model_path(name) is None:
        return {}
    try:
        info = json.loads((shipped_model_dir(name) / "default.json").read_text())
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def default_model_status(name: str = "default") -> str:
    """``""`` when the shipped model ``name`` is installed and validated (see the module docstring), else why
    not."""
    path = default_model_path(name)
    what = "the shipped detector model" if name == "default" else f"the shipped {name} detector model"
    if path is None:
        return f"{what} is not installed" + ("" if name == "default" else " (it comes from vbl-robust harden)")
    if default_model_info(name).get("validated") is not True:
        return f"{what} ({path.name}) does not meet its validation gates yet (see {MODELS_DIR / 'MODEL_CARD.md'})"
    return ""


def default_model_caveats(info: dict[str, Any] | None = None, name: str = "default") -> list[str]:
    """The shipped model's open accuracy goals (``"open_goals"`` of its ``default.json``, or of ``info``), one
    line each."""
    goals = (default_model_info(name) if info is None else info).get("open_goals") or []
    return [str(g) for g in goals] if isinstance(goals, list) else [str(goals)]


def with_design(detector: PoseDetector, design: str, **window):
    """``detector`` as a single pass, or as both passes of a :class:`~vbl_robust.detect.twostage.TwoStageDetector`;
    ``window``: its crop window (``margin``, ``min_side``: what the weights were trained on), two-stage only."""
    if design not in DESIGNS:
        raise ValueError(f"detector design must be one of {DESIGNS}, got {design!r}")
    unknown = set(window) - set(CROP_WINDOW_KEYS)
    if unknown:
        raise ValueError(f"detector crop window: unknown option(s) {sorted(unknown)}; known: {list(CROP_WINDOW_KEYS)}")
    if design == "twostage":
        from .twostage import TwoStageDetector

        return TwoStageDetector(detector, **{k: float(v) for k, v in window.items()})
    if window:
        raise ValueError(f"detector crop window {window} needs design 'twostage', got {design!r}")
    return detector


def default_detector(*, imgsz: int | None = None, chunk: int = 16, design: str | None = None,
                     engine: str = "torch", device: str = "cpu", model: str = "default"):
    """The detector shipped with the package (``model``: which of :data:`SHIPPED_MODELS`); ``design``
    ``"twostage"`` / ``"single"`` (the paper's one pass),
    None → the shipped default (``default.json``, with its crop window ``"twostage": {"min_side": …}`` when the
    weights were trained on another than :class:`~vbl_robust.detect.twostage.TwoStageDetector`'s default); ``engine`` of
    the black-box path (:mod:`.engines`); ``device`` ``auto``/``cpu``/``cuda[:N]`` (:mod:`.device`)."""
    from .engines import with_engine
    from .ultralytics import UltralyticsDetector

    path = default_model_path(model)
    if path is None:
        raise FileNotFoundError(f"{shipped_model_dir(model) / DEFAULT_MODEL.name}: {default_model_status(model)}")
    info = default_model_info(model)
    # the shipped file is part of the installed package: trusted as its code is
    det = UltralyticsDetector(path, trust=True, imgsz=imgsz or info.get("imgsz"), chunk=chunk, device=device)
    design = design or info.get("detector", "single")
    window = dict(info.get("twostage") or {}) if design == "twostage" else {}
    first = info.get("first")
    if first is not None and design == "twostage":  # a crop network behind another shipped model's pass 1
        from .twostage import TwoStageDetector

        pass1 = default_model_path(str(first))
        if first not in SHIPPED_MODELS or first == model or pass1 is None:
            raise FileNotFoundError(f"shipped model {model}: its pass 1, shipped model {first!r}, is not installed")
        one = UltralyticsDetector(pass1, trust=True, imgsz=imgsz or info.get("imgsz"), chunk=chunk, device=device)
        return TwoStageDetector(with_engine(one, engine, trust=True), with_engine(det, engine, trust=True),
                                **{k: float(v) for k, v in window.items()})
    if first is not None:  # a single pass: the shipped model's pass 1 alone is the other model
        raise ValueError(f"shipped model {model} is a pass-2 (crop) network behind {first!r}: it runs two-stage only")
    return with_design(with_engine(det, engine, trust=True), design, **window)


def _model_options(oracle: bool, oracle_noise: float, design: str, engine: str, device: str,
                   noise_needs_oracle: bool) -> dict[str, Any]:
    """:meth:`DetectorSpec.from_choice`'s checks of the detector options; a model's spec options (its design,
    engine and device where they are not the defaults)."""
    if design != "auto" and design not in DESIGNS:
        raise ValueError(f"--detector {design}: choose auto, {' or '.join(DESIGNS)}")
    if oracle and design != "auto":
        raise ValueError("--detector applies to a model, not to --oracle")
    if oracle and engine not in ("auto", "torch"):
        raise ValueError(f"--engine {engine} applies to a model, not to --oracle")
    if oracle and device != "cpu":
        raise ValueError(f"--device {device} applies to a model, not to --oracle (the oracle needs no device)")
    if oracle_noise and not oracle and noise_needs_oracle:
        raise ValueError(f"--oracle-noise {oracle_noise:g} applies to --oracle only")
    opts: dict[str, Any] = {} if design == "auto" else {"design": design}
    if oracle:
        return opts
    from .device import resolve_device
    from .engines import resolve_engine

    try:
        dev = resolve_device(device)
    except ValueError as exc:
        raise ValueError(f"--device {device}: {exc}") from None
    try:
        resolved = resolve_engine(engine, dev)
    except ValueError as exc:
        raise ValueError(f"--engine {engine}: {exc}") from None
    if resolved != "torch":  # torch is every spec's default engine
        opts["engine"] = resolved
    if dev != "cpu":  # the CPU is every spec's default device
        opts["device"] = dev
    return opts


# -- naming and building detectors ------------------------------------------------------------------------------
@dataclass(frozen=True)
class DetectorSpec:
    """How to build a detector.

    Kinds: ``"oracle"`` (projects the ground truth: a perfect detector), ``"default"`` (the shipped model),
    ``"ultralytics"`` (a user's ``.pt``; ``trust=True`` required for files outside the package), ``"onnx"`` (its
    engine for the black box, and a torch twin checked against it for gradient searches: :mod:`.onnx_twin`),
    ``"factory"`` (``path`` = ``"module:callable"`` returning a detector; for tests and plug-ins).
    ``options["design"]`` (model kinds): ``"single"`` or ``"twostage"`` (:func:`with_design`); the shipped model
    defaults to its ``default.json``, a user's model to a single pass; ``options["min_side"]``,
    ``options["margin"]``: a user's two-stage crop window (what the weights were trained on).
    ``options["engine"]``: what runs the black-box forwards (``torch`` default, ``onnxruntime``, ``openvino``, ``auto``; :mod:`.engines`) — it changes
    speed, not outputs (≤ 1e-3 px), so it is recorded in the identity but is not part of the key: a run may resume
    on another engine. ``options["device"]`` (``auto``, ``cpu``, ``cuda[:N]``; :mod:`.device`) likewise: recorded,
    not keyed (a GPU's convolutions differ from the CPU's by ~1e-3 px, far below any error that matters here).
    """

    kind: DetectorKind
    path: str | None = None
    trust: bool = False
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in DETECTOR_KINDS:
            raise ValueError(f"detector kind must be one of {DETECTOR_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "kind", DetectorKind(self.kind))
        if (self.kind.model_file or self.kind == DetectorKind.FACTORY) and not self.path:
            raise ValueError(f"detector kind {self.kind.value!r} needs a path")
        if self.kind.model_file and not Path(self.path).is_file():
            raise FileNotFoundError(f"{self.path}: model file not found")

    @classmethod
    def choose(cls, *, oracle_noise_px: float = 0.0, options: dict[str, Any] | None = None,
               ) -> tuple[DetectorSpec, str]:
        """The shipped model when it is installed and validated, else the oracle: ``(spec, why)`` with ``why``
        ``""`` for the shipped model, else the one-line reason the oracle stands in.

        An undertrained model would turn every audit into a report on a broken detector, so it is used only
        when asked for explicitly (``DetectorSpec("default")``, ``--model default``).
        """
        why = default_model_status()
        if why == "":
            return cls(DetectorKind.DEFAULT, options=dict(options or {})), ""
        return cls.oracle(oracle_noise_px), why

    @classmethod
    def auto(cls, *, oracle_noise_px: float = 0.0) -> DetectorSpec:
        """:meth:`choose`, logging why when the oracle stands in."""
        spec, why = cls.choose(oracle_noise_px=oracle_noise_px)
        if why:
            logger.warning("%s; using the oracle detector (ground-truth keypoints%s)", why,
                           f", {oracle_noise_px:g} px fixed noise" if oracle_noise_px else "")
        return spec

    @classmethod
    def oracle(cls, noise_px: float = 0.0) -> DetectorSpec:
        """The oracle detector, with ``noise_px`` of fixed per-image corner noise (0: exact corners)."""
        return cls(DetectorKind.ORACLE, options={"noise_px": noise_px} if noise_px else {})

    @classmethod
    def from_path(cls, path: str | Path, *, trust: bool = False, option: str = "--model") -> DetectorSpec:
        """A user's model file: ``.onnx`` or ``.pt`` (ultralytics; loads only with ``trust``); ``option`` names it
        in the messages."""
        p = Path(path)
        if p.suffix.lower() == ".onnx":
            return cls(DetectorKind.ONNX, str(p))
        if p.suffix.lower() == ".pt":
            return cls(DetectorKind.ULTRALYTICS, str(p), trust=trust)
        raise ValueError(f"{option} {path}: expected a .pt (ultralytics) or .onnx file")

    @classmethod
    def from_choice(cls, model: str | Path | None = None, *, oracle: bool = False, oracle_noise: float = 0.0,
                    design: str = "auto", engine: str = "torch", device: str = "cpu", trust: bool = False,
                    options: dict[str, Any] | None = None, noise_needs_oracle: bool = True,
                    option: str = "--model", plugin: str | None = None,
                    plugin_digest: str | None = None) -> DetectorSpec:
        """The detector a user chose — the one way every command and workflow makes one.

        ``oracle``: the oracle, with ``oracle_noise`` px of fixed corner noise; else ``model``: a shipped model's
        name (:data:`SHIPPED_MODELS`) or a ``.pt`` / ``.onnx`` file (a ``.pt`` only with ``trust``: it is a
        pickle); else :meth:`choose` (the shipped model once validated, else the oracle with ``oracle_noise``:
        ``kind == "oracle"`` without ``oracle`` says it stands in, :func:`default_model_status` says why).
        ``design``: ``auto`` (the shipped model's own; a user's model as one pass), ``single`` or ``twostage``;
        ``engine`` (:mod:`.engines`) and ``device`` (:mod:`.device`) of a model, resolved here; ``options``: more
        model options (``imgsz``, a crop window). An ``oracle_noise`` without ``oracle`` is refused (it would be
        ignored) unless ``noise_needs_oracle`` is False (the noise of an oracle standing in).

        Raises:
            ValueError: one line naming the command-line option at fault (``option``: the model's own);
                ``FileNotFoundError`` for a model file that is not there.
        """
        opts = _model_options(oracle, oracle_noise, design, engine, device, noise_needs_oracle)
        if oracle and model is not None:
            raise ValueError(f"--oracle and {option} are exclusive")
        if plugin is not None or plugin_digest is not None:
            return cls.plugin(plugin, plugin_digest, trust=trust, taken=(oracle and "--oracle") or
                              (model is not None and option) or (design != "auto" and "--detector") or None)
        if oracle:
            return cls.oracle(oracle_noise)
        opts.update(options or {})
        name = None if model is None else str(model)
        if name in SHIPPED_MODELS:
            if name != "default" and default_model_path(name) is None:
                raise ValueError(f"{option} {name}: {default_model_status(name)}")
            return cls.shipped(name, opts)
        if model is None:
            return cls.choose(oracle_noise_px=oracle_noise, options=opts)[0]
        spec = cls.from_path(model, trust=trust, option=option)
        refuse_without_consent(spec, trust, where=f"{option} ")
        return replace(spec, options=opts) if opts else spec

    @classmethod
    def plugin(cls, target: str | None, digest: str | None = None, *, trust: bool = False,
               taken: str | None = None) -> DetectorSpec:
        """A plug-in detector (:mod:`.plugin`): ``target`` = ``MODULE:FACTORY`` or ``FILE.py:FACTORY``; ``digest``
        = the SHA-256 of its weights as the user states it (64 hex digits; part of its identity); ``taken``: an
        option that chose another detector (refused: one detector per run). Building it imports the user's code:
        ``trust`` is the consent (the command line's ``--detector-plugin`` gives it; a value from data does not)."""
        if target is None:
            raise ValueError("--plugin-digest needs --detector-plugin")
        if taken:
            raise ValueError(f"--detector-plugin and {taken} are exclusive (one detector per run)")
        from .plugin import parse_plugin

        parse_plugin(target)
        if digest is not None and not re.fullmatch(r"[0-9a-fA-F]{64}", digest):
            raise ValueError(f"--plugin-digest {digest}: expected the SHA-256 of the weights, 64 hex digits")
        spec = cls(DetectorKind.PLUGIN, target, trust=trust, options={} if digest is None else {"weights_sha256": digest.lower()})
        refuse_without_consent(spec, trust, where="--detector-plugin ")
        return spec

    @classmethod
    def from_identity(cls, ident: Mapping[str, Any], *, trust: bool = False, where: str = "") -> DetectorSpec:
        """The spec a run recorded (:meth:`identity`, as stored with its campaign): to run more jobs with the same
        detector. A stored identity is data: one that names code (:func:`~vbl_robust.consent.consent_needed`: a factory or plug-in's
        ``module:callable``, a ``.pt`` outside the package) is refused unless ``trust`` (``--trust-model``) —
        ``ValueError``, one line beginning with ``where``, before anything is imported or loaded."""
        if not isinstance(ident, Mapping):
            raise ValueError(f"{where}the stored detector is not a detector identity ({type(ident).__name__})")
        refuse_without_consent(ident, trust, where=where)
        kind = ident.get("kind")
        path = ident.get("factory") if kind in CODE_KINDS else ident.get("path")
        options = ident.get("options") or {}
        if not isinstance(options, Mapping):
            raise ValueError(f"{where}the stored detector's options are not a mapping ({type(options).__name__})")
        return cls(kind, path if kind in (DetectorKind.ULTRALYTICS, DetectorKind.ONNX, *CODE_KINDS) else None,
                   trust=trust,
                   options=dict(options))

    @classmethod
    def shipped(cls, name: str = "default", options: dict[str, Any] | None = None) -> DetectorSpec:
        """A model shipped with the package (:data:`SHIPPED_MODELS`; the default model's spec names none, so its
        runs' keys stay as they were)."""
        shipped_model_dir(name)
        return cls(DetectorKind.DEFAULT, options={**dict(options or {}), **({} if name == "default" else {"model": name})})

    @property
    def shipped_name(self) -> str | None:
        """Which shipped model (``kind == "default"``), else None."""
        return self.options.get("model", "default") if self.kind == DetectorKind.DEFAULT else None

    @property
    def model_file(self) -> Path | None:
        """The file whose SHA-256 identifies the detector: the weights, or a plug-in's source file."""
        if self.kind == DetectorKind.DEFAULT:
            return default_model_path(self.shipped_name)
        if self.kind.model_file:
            return Path(self.path)
        if self.kind == DetectorKind.PLUGIN:
            from .plugin import plugin_source

            return plugin_source(self.path)
        return None

    @property
    def name(self) -> str:
        if self.kind == DetectorKind.ORACLE:
            return "oracle (ground-truth keypoints)"
        if self.kind == DetectorKind.DEFAULT:
            which = "" if self.shipped_name == "default" else f"{self.shipped_name} "
            return f"shipped {which}model ({self.model_file.name if self.model_file else 'missing'})"
        return f"{self.kind.value}: {self.path}"

    def identity(self) -> dict[str, Any]:
        """JSON identity: kind, name, model file SHA-256 (None for the oracle), options; for the shipped model
        also the SHA-256 of its ``default.json`` (single or two-stage, input size)."""
        f = self.model_file
        ident = {"kind": self.kind.value, "name": self.name, "path": None if f is None else str(f),
                 "sha256": None if f is None else file_sha256(f), "options": dict(self.options)}
        if self.kind.runs_code:
            ident["factory"] = self.path
        if self.kind.pose_model:
            from .device import resolve_device
            from .engines import resolve_engine

            ident["device"] = resolve_device(self.options.get("device", "cpu"))
            ident["engine"] = resolve_engine(self.options.get("engine", self.kind.default_engine), ident["device"])
            ident["precision"] = "fp32"
        ident["design"], ident["input_size"] = self.design()
        if self.kind == DetectorKind.DEFAULT and f is not None and (f.parent / "default.json").is_file():
            ident["config_sha256"] = file_sha256(f.parent / "default.json")
            info = default_model_info(self.shipped_name)
            if info.get("first") in SHIPPED_MODELS and (one := default_model_path(str(info["first"]))) is not None:
                ident["first_sha256"] = file_sha256(one)  # pass 1 is another file: part of what decides outputs
            if "version" in info:
                ident["name"] += f" v{info['version']}"
            if goals := default_model_caveats(info):
                ident["open_goals"] = goals
        return ident

    def design(self) -> tuple[str | None, int | None]:
        """The pipeline this detector runs as a report names it: ``("single pass" | "two-stage" | "oracle", input
        size in px)``; the input size is None where the model file states it (a user's model at its own size), the
        design None for a factory's detector (its own)."""
        if self.kind == DetectorKind.ORACLE:
            return "oracle", None
        if self.kind.runs_code:
            return None, None
        info = default_model_info(self.shipped_name) if self.kind == DetectorKind.DEFAULT else {}
        design = self.options.get("design") or info.get("detector", "single")
        size = self.options.get("imgsz") or info.get("imgsz")
        return {"single": "single pass", "twostage": "two-stage"}.get(design, design), (int(size) if size else None)

    def key(self) -> str:
        """Digest of what determines the detector's outputs (not where the file lives; the design and input size
        named in the identity are its options' and the shipped ``default.json``'s, digested there)."""
        ident = self.identity()
        ident["options"] = {k: v for k, v in ident["options"].items() if k not in ("engine", "device")}
        skip = ("name", "path", "engine", "precision", "device", "design", "input_size")
        return digest({k: v for k, v in ident.items() if k not in skip}, 24)

    def build(self) -> Any:
        """Construct the detector (call once per process; models are heavy): :data:`BUILDERS` of its kind."""
        return BUILDERS[self.kind](self)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind.value, "path": self.path, "trust": self.trust, "options": dict(self.options)}


def _build_oracle(spec: DetectorSpec) -> Any:
    from .oracle import OracleDetector

    return OracleDetector(**spec.options)


def _build_default(spec: DetectorSpec) -> Any:
    return default_detector(**spec.options)


def _model_file_options(spec: DetectorSpec) -> tuple[dict[str, Any], str, dict[str, Any], str]:
    """A user's model file's options split: ``(model options, design, crop window, engine)``."""
    opts = dict(spec.options)
    design = opts.pop("design", "single")
    window = {k: opts.pop(k) for k in CROP_WINDOW_KEYS if k in opts}
    engine = opts.pop("engine", spec.kind.default_engine)
    return opts, design, window, engine


def _build_onnx(spec: DetectorSpec) -> Any:
    from .engines import resolve_engine
    from .onnx_twin import with_twin

    opts, design, window, engine = _model_file_options(spec)
    resolved = resolve_engine(engine)
    if resolved == "openvino":
        from .openvino import OpenVinoDetector

        return with_design(with_twin(OpenVinoDetector(spec.path, **opts), resolved), design, **window)
    if resolved == "torch":
        raise ValueError(f"{spec.path}: an ONNX model runs on onnxruntime or openvino, not torch")
    from .onnx import OnnxDetector

    return with_design(with_twin(OnnxDetector(spec.path, **opts), resolved), design, **window)


def _build_ultralytics(spec: DetectorSpec) -> Any:
    from .engines import with_engine
    from .ultralytics import UltralyticsDetector

    opts, design, window, engine = _model_file_options(spec)
    model = UltralyticsDetector(spec.path, trust=spec.trust, **opts)
    return with_design(with_engine(model, engine, trust=spec.trust), design, **window)


def _build_plugin(spec: DetectorSpec) -> Any:
    from .plugin import build_plugin

    return build_plugin(spec.path)


def _build_factory(spec: DetectorSpec) -> Any:
    module, _, attr = spec.path.partition(":")
    return getattr(importlib.import_module(module), attr)(**spec.options)


#: How :meth:`DetectorSpec.build` makes a detector of each kind (the perturbation registry's pattern: one entry
#: per kind, looked up, never switched on).
BUILDERS: dict[DetectorKind, Callable[[DetectorSpec], Any]] = {
    DetectorKind.ORACLE: _build_oracle,
    DetectorKind.DEFAULT: _build_default,
    DetectorKind.ULTRALYTICS: _build_ultralytics,
    DetectorKind.ONNX: _build_onnx,
    DetectorKind.FACTORY: _build_factory,
    DetectorKind.PLUGIN: _build_plugin,
}
