"""What the campaign commands (audit, demo, risk, reproduce, truth) read together: one frozen request per family of
options, built from the command's parameters by :meth:`~_Request.of` (its fields are the parameters' names; the
options themselves are declared once in :mod:`.options`) and passed down to the library:

- :class:`ImagesRequest` (``--n``, ``--seed``, ``--lard``, ``--width``, ``--height``) → the samples
  (:func:`vbl_robust.campaigns.samples.load_samples`);
- :class:`DetectorRequest` (``--model``, ``--trust-model``, ``--detector``, ``--engine``, ``--device``, ``--oracle``,
  ``--oracle-noise``, ``--detector-plugin``, ``--plugin-digest``) → a
  :class:`~vbl_robust.detect.shipped.DetectorSpec`;
- :class:`BoxRequest` (``--roll``, ``--contrast``, ``--perturb``) → a :class:`~vbl_robust.specs.campaign.BoxSpec`;
- :class:`RunRequest` (``--executor``, ``--address``, ``--workers``, ``--clock``, ``--wait``, ``--retry-failed``,
  ``--allow-unmeasured``) → the run into the store (:func:`.run.run_with_progress`, which calls
  :func:`vbl_robust.campaigns.runner.run_campaign`; each job's objective: :func:`vbl_robust.campaigns.work.build_objective`);
- :class:`ExportRequest` (``--csv``, ``--parquet``, ``--report``) → the exports and the report (:func:`.run.finish`).

A field a command has no option for keeps its default (``risk`` has no ``--clock``: ``auto``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

from .common import detector_spec, parse_box
from .options import DEFAULT_IMAGES
from .run import check_executor, check_exports, finish, load, run_settings, run_with_progress

if TYPE_CHECKING:  # torch behind them: imported where they are built, so that ``vbl-robust --help`` stays instant
    from vbl_robust.campaigns.runner import RunSummary
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.specs.campaign import BoxSpec, CampaignSpec

__all__ = ["BoxRequest", "DetectorRequest", "ExportRequest", "ImagesRequest", "RunRequest"]


class _Request:
    """A family of a command's parameters."""

    @classmethod
    def of(cls, params: Mapping[str, Any], **given: Any) -> Self:
        """The request of the command's ``params`` (by parameter name; ``given`` first: a command whose option has
        another name, e.g. ``reproduce --images``)."""
        values = {**params, **given}
        return cls(**{f.name: values[f.name] for f in fields(cls) if f.name in values})  # type: ignore[call-arg]


@dataclass(frozen=True)
class ImagesRequest(_Request):
    """The images of a run: ``n`` of them (None: a default, or all rows of a smaller ``lard`` dataset)."""

    n: int | None
    seed: int
    lard: Path | None = None
    width: int = 1024
    height: int = 1024

    def load(self, default: int = DEFAULT_IMAGES) -> tuple[list, dict]:
        """The samples and their source (provenance), or one line."""
        return load(self.n, self.seed, self.lard, self.width, self.height, default=default)


@dataclass(frozen=True)
class DetectorRequest(_Request):
    """The detector the user chose (:meth:`DetectorSpec.from_choice
    <vbl_robust.detect.shipped.DetectorSpec.from_choice>`)."""

    model: Path | None = None
    trust_model: bool = False
    design: str = "auto"
    engine: str = "auto"
    device: str = "cpu"
    oracle: bool = False
    oracle_noise: float = 0.0
    detector_plugin: str | None = None
    plugin_digest: str | None = None

    def spec(self, *, noise_needs_oracle: bool = True) -> DetectorSpec:
        """The detector's spec, or one line (:func:`.common.detector_spec`, with its notes on standard error)."""
        return detector_spec(self.model, self.trust_model, self.oracle, self.oracle_noise, self.design, self.engine,
                             self.device, noise_needs_oracle=noise_needs_oracle, plugin=self.detector_plugin,
                             plugin_digest=self.plugin_digest)


@dataclass(frozen=True)
class BoxRequest(_Request):
    """The perturbation box Θ: roll, contrast and any other family (:func:`.common.parse_box`)."""

    roll: str = "15"
    contrast: str | None = None
    perturb: list[str] | None = None

    def spec(self) -> BoxSpec:
        """The box spec, or one line naming the option at fault."""
        return parse_box(self.roll, self.contrast, self.perturb)


@dataclass(frozen=True)
class RunRequest(_Request):
    """How a campaign runs: executor, workers, the clock of time budgets, what it does with a store in use and with
    jobs not measured."""

    executor: str = "local"
    address: str | None = None
    workers: int = 0
    clock: str = "auto"
    wait: bool = False
    retry_failed: bool = False
    allow_unmeasured: bool = False

    def check(self) -> None:
        """``--executor`` and ``--address`` checked before any work, or one line."""
        check_executor(self.executor, self.address)

    def settings(self, spec: CampaignSpec, device: str) -> tuple[CampaignSpec, int]:
        """``spec`` on the run's clock, and the worker count (:func:`.run.run_settings`)."""
        return run_settings(spec, self.clock, device, self.workers)

    def run(self, spec: CampaignSpec, samples: list, out: Path, detector: DetectorSpec, *, source: dict,
            config: dict, quiet: bool, workers: int) -> RunSummary:
        """Run ``spec`` into ``out`` with a progress bar (:func:`.run.run_with_progress`); ``workers``: the count
        :meth:`settings` resolved."""
        return run_with_progress(spec, samples, out, detector, executor=self.executor, address=self.address,
                                 source=source, config=config, quiet=quiet, workers=workers, wait=self.wait,
                                 retry_failed=self.retry_failed, allow_unmeasured=self.allow_unmeasured)


@dataclass(frozen=True)
class ExportRequest(_Request):
    """What a finished run writes besides its store: CSV, Parquet, the HTML report."""

    csv: Path | None = None
    parquet: Path | None = None
    report: bool = True

    def check(self, out: Path | None) -> None:
        """Refuse before the run an export it could not write at its end (and an ``out`` that is a file)."""
        check_exports(self.csv, self.parquet, out)

    def finish(self, out: Path, summary: RunSummary, *, quiet: bool, allow_unmeasured: bool) -> bool:
        """The summary table, the exports and the report of ``out`` (:func:`.run.finish`): False when the run is
        incomplete or, unless ``allow_unmeasured``, some job was not measured."""
        return finish(out, summary, csv=self.csv, parquet=self.parquet, report=self.report, quiet=quiet,
                      allow_unmeasured=allow_unmeasured)
