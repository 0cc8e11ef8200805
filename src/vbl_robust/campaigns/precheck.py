"""What is checked before a campaign's first job, so that a job the tool cannot complete is refused up front rather
than found during the run: each method of the campaign can run on the detector (a gradient search needs a detector
with a differentiable path), each image of the run is present, decodes and has the size its camera model states,
and a plug-in detector runs on the run's first image. A refusal is one ``ValueError`` line naming the option and the value; nothing is stored before it.

What still fails during a run (a file deleted meanwhile, an exception in the detector) is recorded as *not measured*
(:class:`~vbl_robust.constants.NotMeasured`), never as a finding.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..consent import DetectorKind
from ..constants import NotMeasured
from ..specs.campaign import CampaignSpec
from .provenance import DetectorSpec

__all__ = ["check_images", "check_methods", "check_plugin", "check_run", "gradient_methods"]


def gradient_methods(spec: CampaignSpec) -> list[str]:
    """The methods of ``spec`` that need the detector's gradients (APGD), in the spec's order."""
    from ..search.api import METHODS

    found = dict.fromkeys(m for blk in spec.blocks for m in blk.methods)
    return [m for m in found if m in METHODS and METHODS[m].needs_gradient]


def check_methods(methods: Sequence[str], detector: Any, name: str, *, monitor_sigma: bool = False) -> None:
    """``ValueError`` (one line) when a method of ``methods`` cannot run on ``detector`` (built; ``name`` is how the
    user named it): a gradient search on a detector without a differentiable path (its ``gradient_unavailable``
    says why, e.g. an ONNX model whose torch twin could not be checked), or under the σ monitor
    (``monitor_sigma``). The line names the gradient-free methods to choose instead."""
    from ..search.api import METHODS

    needs = [m for m in dict.fromkeys(methods) if m in METHODS and METHODS[m].needs_gradient]
    if not needs:
        return
    free = [m for m in METHODS if not METHODS[m].needs_gradient]
    instead = f"{', '.join(free[:-1])} or {free[-1]}"
    if not (getattr(detector, "differentiable", False) and callable(getattr(detector, "detect_top", None))):
        why = getattr(detector, "gradient_unavailable", "") or "it has no differentiable path"
        raise ValueError(f"--methods {','.join(needs)}: {NotMeasured.METHOD_UNFIT.value} — the detector {name} gives "
                         f"no gradient ({why}); use a black-box method instead: {instead}")
    if monitor_sigma:
        raise ValueError(f"--methods {','.join(needs)}: {NotMeasured.METHOD_UNFIT.value} — the σ monitor reads the "
                         f"black-box path, a gradient search cannot run under it; use a black-box method instead: "
                         f"{instead}")


def check_images(samples: Sequence[Any]) -> None:
    """``ValueError`` (one line) naming the first image of the run (the frames of approach sequences included) that
    is missing, does not decode, or has another size than its camera model states, and how many more have a
    problem (:func:`vbl_robust.data.check.first_problem`)."""
    from ..data.check import first_problem

    problem = first_problem(samples)
    if problem:
        raise ValueError(f"{NotMeasured.INPUT_UNAVAILABLE.value}: {problem}; nothing was run or stored")


def check_run(spec: CampaignSpec, samples: Sequence[Any], detector: DetectorSpec, *, images: bool = True) -> None:
    """Everything checked before a campaign's first job (module docstring): ``ValueError``, one line. ``images``
    False leaves the images to the run (``--allow-unmeasured``: an unreadable one's jobs are then not measured, and
    the others are run); the methods are checked either way."""
    from .work import detector_for

    if images:
        check_images(samples)
    needs = gradient_methods(spec)
    if needs:
        check_methods(needs, detector_for(detector), detector.name, monitor_sigma=spec.settings.monitor_sigma_m is not None)
    if detector.kind == DetectorKind.PLUGIN and samples:
        check_plugin(spec, samples[0], detector)


def check_plugin(spec: CampaignSpec, sample: Any, detector: DetectorSpec) -> None:
    """``ValueError`` (one line) unless the plug-in detector runs on the run's first sample: one evaluation at the
    centre of the first box, through the whole pipeline (its ``detect`` must return one
    :class:`~vbl_robust.detect.Detections` per view). A detector that raises here would leave every job not
    measured; what it finds (no detection, a bad pose) is no refusal — that is the pipeline's outcome."""
    import numpy as np

    from .work import build_objective, detector_for

    box = next(b.box for blk in spec.blocks for b in blk.boxes)
    centre = np.asarray(box.center, dtype=np.float64)[None]
    try:
        build_objective(sample, detector_for(detector), box, spec.settings).evaluate(centre)
    except Exception as exc:  # noqa: BLE001 - whatever the user's code raises is one line here
        text = str(exc).splitlines()[0] if str(exc) else ""
        raise ValueError(f"--detector-plugin {detector.path}: {NotMeasured.DETECTOR_ERROR.value} on the run's first "
                         f"image ({sample.id}): {type(exc).__name__}{': ' + text if text else ''}; nothing was run "
                         "or stored") from None
