"""The worst-case gallery: per breached image, most severe first and at most
:data:`~vbl_robust.report.evidence.WORST_CASES`, the perturbed view at θ* beside the unperturbed one with the true
and the predicted corners drawn, θ*, the error and its kind.

The cases are the evidence's (:func:`vbl_robust.report.evidence.worst_cases`: misleading breaches before
flagged-only ones, then the larger error). Everything printed comes from the store: θ* (the search's worst point),
its error, the breach kind, the predicted corners and their confidence (stored with each main job from schema 4
on; older rows have none, and the entry says so). The pixels are not in the store: each image is rebuilt from the
run's recorded dataset source (:func:`vbl_robust.campaigns.truth.load_run_samples`: synthetic images regenerated,
LARD rows read again), checked against the store (the geometry fingerprint; an image file's SHA-256, when its jobs
recorded one), and perturbed at θ* (deterministic; at the image's own resolution, where the pipeline may have
worked on a resized copy). Where that is not possible (another machine without the dataset, a changed file), the
entry is shown without its picture, with the reason.

Pictures: ``figures/gallery_NN.png`` beside the report (two crops around the runway, about 700 × 400 px, a
palette of :data:`GALLERY_COLORS` colours), also embedded in the page.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from ..campaigns.truth import load_run_samples
from ..constants import BreachKind
from . import figures as F
from .evidence import Evidence, WorstCase
from .html import esc, fmt_num
from .rows import Context, Section, theta_text

logger = logging.getLogger(__name__)

__all__ = ["NO_CANDIDATE", "case_figure", "section_gallery"]

#: Colours of a gallery picture's palette (a PNG of about 60 kB instead of 300 kB).
GALLERY_COLORS = 256

#: Failure reasons after which the detector selected no candidate (so no corners were predicted).
NO_CANDIDATE = frozenset({"no_detection", "low_confidence", "non_finite_keypoints",
                          "out_of_view"})


def _samples(ctx: Context, ids: Sequence[str]) -> tuple[dict[str, Any], str]:
    """The samples ``ids`` rebuilt from the run's dataset source, or ({}, why not)."""
    if getattr(ctx.spec, "sustain", None) is not None:
        return {}, "a sequence campaign: each case is an approach sequence (its frames: the sequence section)"
    try:
        return {s.id: s for s in load_run_samples(ctx.store, ids)}, ""
    except (ValueError, KeyError, TypeError, OSError) as exc:
        return {}, f"the {ctx.spec.unit}s cannot be rebuilt here ({type(exc).__name__}: {exc})"


def _differs(ctx: Context, sample: Any, digests: dict[str, str]) -> str:
    """Why the rebuilt ``sample`` is not the one its jobs ran on ("" when it is)."""
    from ..campaigns.provenance import sample_fingerprint
    from ..digest import file_sha256

    stored = (ctx.samples.get(sample.id) or {}).get("fingerprint")
    if stored and stored != sample_fingerprint(sample):
        return "its rebuilt geometry differs from the stored one"
    path, digest = getattr(sample, "image_path", None), digests.get(sample.id)
    if path is not None and digest:
        if not Path(path).is_file():
            return f"its image file {path} is not on this machine"
        if file_sha256(path) != digest:
            return f"its image file {path} differs from the one its jobs read"
    return ""


def case_figure(case: WorstCase, sample: Any) -> Any:
    """The :func:`~vbl_robust.report.figures.worst_view` figure of ``case`` on its rebuilt ``sample``: the image
    perturbed at θ* (``ValueError``/``OSError`` when its pixels cannot be read)."""
    from ..perturb import Perturbation

    image = np.asarray(sample.image)
    theta = case.theta or {}
    if theta:
        names = tuple(theta)
        t = np.array([[theta[n] for n in names]], dtype=np.float64)
        pert = Perturbation(names)
        perturbed = np.clip(pert.images_numpy(image, t, K=sample.K)[0], 0.0, 1.0)
        true_after = np.asarray(pert.points(sample.corners_2d, t, K=sample.K)[0], dtype=np.float64)
    else:
        perturbed, true_after = image, np.asarray(sample.corners_2d, dtype=np.float64)
    pred = None if case.corners is None else np.asarray(case.corners, dtype=np.float64)
    return F.worst_view(image, perturbed, np.asarray(sample.corners_2d, dtype=np.float64), true_after, pred,
                        confident=not case.reason)


def _kind_text(case: WorstCase) -> str:
    if case.kind == BreachKind.MISLEADING.value:
        return '<span class="kind-misleading">misleading</span> (a confident pose, off by more than ε_safe)'
    if case.kind == BreachKind.FLAGGED.value:
        return '<span class="kind-flagged">flagged only</span> (the system knows it has no fix)'
    return "unknown (the row's points are not stored)"


def _facts(ctx: Context, rank: int, case: WorstCase, picture: str) -> str:
    """The text of one entry: what, where, how bad."""
    reason = ("a pose" if case.reason == "" else "unknown" if case.reason is None
              else f"no pose: <code>{esc(case.reason)}</code> (counted as the {ctx.spec.penalty_m:g} m penalty)")
    conf = "–" if case.conf is None else f"{case.conf:.2f} (τ_conf = {ctx.spec.conf_threshold:g})"
    if case.corners is not None:
        corners = "drawn (red)"
    elif case.reason in NO_CANDIDATE:
        corners = "none (no candidate selected)"
    else:
        corners = "not stored (a row written before schema 4, or read off a longer run)"
    items = [("kind", _kind_text(case)), ("error at θ*", f"{fmt_num(case.worst_m)} m (ε_safe = {ctx.eps:g} m)"),
             ("θ*", esc(theta_text(case.theta) or "–")), ("at θ*", reason), ("confidence", conf),
             ("box", esc(case.box_label)),
             ("found by", esc(F.style(case.method)["label"]) + (f", {esc(case.budget_label)}" if case.budget_label
                                                               else "")),
             ("predicted corners", corners)]
    if case.position_sigma_m is not None:  # a detector that says how sure it is
        monitor = ctx.spec.monitor_sigma_m
        verdict = "" if monitor is None else (f" — above the σ monitor's {monitor:g} m" if case.position_sigma_m >
                                              monitor else f" — within the σ monitor's {monitor:g} m")
        items.insert(5, ("position σ", f"{fmt_num(case.position_sigma_m)} m (the corners' σ through PnP){verdict}"))
    if case.kind == BreachKind.MISLEADING.value and case.reason and case.confident_m is not None:
        items.insert(2, ("misleading pose", f"elsewhere in Θ: the search's largest confident-pose error is "
                                            f"{fmt_num(case.confident_m)} m"))
    if picture:
        items.append(("picture", esc(picture)))
    dl = "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in items)
    return f'<div class="facts"><h3>#{rank} {esc(ctx.spec.unit)} {esc(case.sample_id)}</h3><dl>{dl}</dl></div>'


def section_gallery(ctx: Context, ev: Evidence) -> Section | None:
    """The gallery of ``ev.worst`` (module docstring); None when nothing was breached."""
    if not ev.worst:
        return None
    unit = ctx.spec.unit
    s = Section(f"Worst cases: the {len(ev.worst)} most severe of {ev.breached} breached {unit}s")
    s.html.append(
        f"<p>One entry per breached {unit}, at its most severe breach over every method and box: misleading "
        "breaches first (the system does not know it is wrong), then flagged-only ones (it knows it has no fix), "
        "each by its error, largest first. Left: the unperturbed image with its true corners (green, the larger "
        "circle is corner TR; order TR, TL, BL, BR); right: the image perturbed at θ*, the search's worst point, "
        "with the true corners moved by the perturbation and the corners the detector predicted there (red "
        "crosses). Each picture is a crop around the runway; the images are rebuilt from the run's dataset "
        "source and perturbed at θ* here (the store holds θ*, the error, the kind and the predicted corners).</p>")
    samples, why = _samples(ctx, [w.sample_id for w in ev.worst])
    if why:
        s.html.append(f'<p class="warn">No pictures: {esc(why)}.</p>')
    digests = ctx.store.image_digests() if samples else {}
    for rank, case in enumerate(ev.worst, start=1):
        sample, figure, note = samples.get(case.sample_id), "", ""
        if sample is not None:
            note = _differs(ctx, sample, digests)
            if not note:
                try:
                    fig = case_figure(case, sample)
                    figure = ctx.figure(fig, f"gallery_{rank:02d}", "", colors=GALLERY_COLORS)
                except Exception as exc:  # one image that cannot be drawn must not hide the others
                    logger.warning("gallery: %s %s not drawn: %s", unit, case.sample_id, exc)
                    plt.close("all")
                    note = f"its picture cannot be made here ({type(exc).__name__}: {exc})"
                finally:
                    sample.drop_pixels()
        elif samples:
            note = "not in the rebuilt dataset"
        s.html.append(f'<div class="case">{figure}{_facts(ctx, rank, case, note and f"not drawn: {note}")}</div>')
    return s
