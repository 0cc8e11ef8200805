"""The worst-case gallery: per breached image, most severe first and at most
:data:`~vbl_robust.report.evidence.WORST_CASES`, the perturbed view at θ* beside the unperturbed one, the true and
the predicted corners drawn on both, θ*, the error and its kind, the error unperturbed L(0), each corner's shift in
pixels and what a pixel is worth in metres at the image's distance (:func:`geometry_text`).

The cases are the evidence's (:func:`vbl_robust.report.evidence.worst_cases`: misleading breaches before
flagged-only ones, then the larger error). Everything printed comes from the store: θ* (the search's worst point),
its error, the breach kind, the predicted corners and their confidence (stored with each main job from schema 4
on; older rows have none, and the entry says so), L(0) with the corners predicted unperturbed (payload
``nominal``; older stores: "–"). An image whose L(0) is already above ε_safe / 2 is marked: the perturbation did
not break a sound pose there. The pixels are not in the store: each image is rebuilt from the run's recorded
dataset source (:func:`vbl_robust.analysis.truth.load_run_samples`: synthetic images regenerated, LARD rows read
again), checked against the store (the geometry fingerprint; an image file's SHA-256, when its jobs recorded one),
and perturbed at θ* (deterministic; at the image's own resolution, where the pipeline may have worked on a resized
copy). Where that is not possible (another machine without the dataset, a changed file), the entry is shown
without its picture, with the reason.

Pictures: ``figures/gallery_NN.png`` beside the report (two crops scaled to the runway, drawn pixel by pixel, about
800 × 470 px, a palette of :data:`GALLERY_COLORS` colours), embedded in the page too (``vbl-robust report``: one
file holds the report) or shown from those files (a committed bundle: the gallery is most of a page's weight, about
0.8 MB of base64 for twelve cases; see :func:`~vbl_robust.report.build.build_report`'s ``embed``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from ..analysis.truth import load_run_samples
from ..constants import BreachKind, FailureReason
from ..specs.kinds import SourceKind
from .evidence import Evidence, WorstCase
from .figure_style import style
from .html import esc, fmt_num
from .rows import Context, Section, theta_text
from .view_figure import corner_shifts, shifts_text, worst_view

logger = logging.getLogger(__name__)

__all__ = ["NO_CANDIDATE", "case_figure", "geometry_text", "metres_per_pixel", "section_gallery"]

#: Colours of a gallery picture's palette (a PNG of about 60 kB instead of 300 kB).
GALLERY_COLORS = 256

#: Failure reasons after which the detector selected no candidate (so no corners were predicted).
NO_CANDIDATE = frozenset({FailureReason.NO_DETECTION, FailureReason.LOW_CONFIDENCE,
                          FailureReason.NON_FINITE_KEYPOINTS, FailureReason.OUT_OF_VIEW})


def _samples(ctx: Context, ids: Sequence[str]) -> tuple[dict[str, Any], str]:
    """The samples ``ids`` rebuilt from the run's dataset source, or ({}, why not)."""
    if ctx.spec.settings.sustain is not None:
        return {}, "a sequence campaign: each case is an approach sequence (its frames: the sequence section)"
    runs = ctx.store.runs()
    source = ((runs[-1].provenance.dataset if runs else None) or {}).get("source") or {}
    if source.get("kind") == SourceKind.TRUTH:  # vbl-robust truth: the images of the run it checks, named, not recorded
        return {}, (f"a truth run grids {ctx.spec.unit}s of the run it checks ({source.get('run')}); their pictures "
                    "are in that run's gallery")
    try:
        return {s.id: s for s in load_run_samples(ctx.store, ids)}, ""
    except (ValueError, KeyError, TypeError, OSError) as exc:
        # without the store's path: a packed store is read through a temporary copy, whose name means nothing
        why = str(exc).removeprefix(f"{ctx.store.path}: ")
        return {}, f"the {ctx.spec.unit}s cannot be rebuilt here ({type(exc).__name__}: {why})"


def _differs(ctx: Context, sample: Any, digests: dict[str, str]) -> str:
    """Why the rebuilt ``sample`` is not the one its jobs ran on ("" when it is)."""
    from ..campaigns.provenance import sample_fingerprint
    from ..digest import file_sha256

    stored = ctx.samples[sample.id].fingerprint if sample.id in ctx.samples else None
    if stored and stored != sample_fingerprint(sample):
        return "its rebuilt geometry differs from the stored one"
    path, digest = getattr(sample, "image_path", None), digests.get(sample.id)
    if path is not None and digest:
        if not Path(path).is_file():
            return f"its image file {path} is not on this machine"
        if file_sha256(path) != digest:
            return f"its image file {path} differs from the one its jobs read"
    return ""


def true_after(case: WorstCase, sample: Any) -> np.ndarray:
    """``(4, 2)`` the sample's true corners moved by the perturbation at θ* (its pixels)."""
    from ..perturb.compose import Perturbation

    theta = case.theta or {}
    if not theta:
        return np.asarray(sample.corners_2d, dtype=np.float64)
    names = tuple(theta)
    t = np.array([[theta[n] for n in names]], dtype=np.float64)
    return np.asarray(Perturbation(names).points(sample.corners_2d, t, K=sample.K)[0], dtype=np.float64)


def _metres(v: float | None) -> str:
    return "–" if v is None else f"{fmt_num(float(v))} m"


def case_figure(case: WorstCase, sample: Any) -> Any:
    """The :func:`~vbl_robust.report.view_figure.worst_view` figure of ``case`` on its rebuilt ``sample``: the image
    perturbed at θ*, the corners predicted there and unperturbed (``ValueError``/``OSError`` when its pixels cannot
    be read)."""
    from ..perturb.compose import Perturbation

    image = np.asarray(sample.image)
    theta = case.theta or {}
    if theta:
        names = tuple(theta)
        t = np.array([[theta[n] for n in names]], dtype=np.float64)
        perturbed = np.clip(Perturbation(names).images_numpy(image, t, K=sample.K)[0], 0.0, 1.0)
    else:
        perturbed = image
    pred = None if case.corners is None else np.asarray(case.corners, dtype=np.float64)
    pred0 = None if case.nominal_corners is None else np.asarray(case.nominal_corners, dtype=np.float64)
    titles = (f"unperturbed: L(0) = {_metres(case.nominal_m)}", f"perturbed at θ*: L = {_metres(case.worst_m)}")
    return worst_view(image, perturbed, np.asarray(sample.corners_2d, dtype=np.float64), true_after(case, sample),
                        pred, predicted_before=pred0, confident=not case.reason, titles=titles)


def metres_per_pixel(sample: Any) -> tuple[float, float, float, float]:
    """``(m, D, W, f)``: about how far (metres) the position moves per pixel a corner moves, ``m = D · (1 / f) ·
    (D / W)`` — at slant distance ``D`` (m) the runway's near edge of width ``W`` (m) spans ``w = f W / D`` pixels
    (pinhole, focal length ``f`` px), PnP reads the range from that scale, and a change δ of ``w`` changes the range
    by ``D δ / w``. An order of magnitude, checked against PnP (tests): one near corner moved 1 px sideways moves
    the position by 0.5–1.5 × ``m``."""
    D = float(sample.slant_distance_m)
    W = float(np.linalg.norm(np.asarray(sample.corners_3d)[2] - np.asarray(sample.corners_3d)[3]))
    f = float(np.asarray(sample.K)[0, 0])
    return D * D / (f * W), D, W, f


def geometry_text(sample: Any) -> str:
    """One line: what a pixel is worth in metres at this image's distance (:func:`metres_per_pixel`)."""
    m, D, W, f = metres_per_pixel(sample)
    return (f"at slant distance D = {D / 1000:.1f} km the runway's near edge (W = {W:.0f} m) spans f·W/D ≈ "
            f"{f * W / D:.1f} px (f = {f:.0f} px); PnP reads the range from that scale, so a corner shift of δ px "
            f"moves the position by about D·δ/f·(D/W) ≈ {fmt_num(m)} m per pixel (pinhole model)")


def nominal_text(case: WorstCase, eps: float, conf_threshold: float) -> str:
    """L(0) for the facts: the error unperturbed, what the pipeline gave and a mark where it is already above
    ε_safe / 2 (HTML)."""
    if case.nominal_m is None:
        return "– (not stored: a run from before L(0) was)"
    how = ("a pose" + (f", confidence {case.nominal_conf:.2f}" if case.nominal_conf is not None else "")
           if not case.nominal_reason else f"no pose: <code>{esc(case.nominal_reason)}</code>, the penalty")
    text = f"{fmt_num(float(case.nominal_m))} m ({how})"
    if case.nominal_m > eps:
        text += ' — <span class="nominal-warn">fails unperturbed</span>: the perturbation did not break a sound pose'
    elif case.nominal_m > eps / 2:
        text += (f' — <span class="nominal-warn">nearly fails unperturbed</span> (above ε_safe / 2 = '
                 f"{eps / 2:g} m)")
    return text


def _kind_text(case: WorstCase) -> str:
    if case.kind == BreachKind.MISLEADING.value:
        return '<span class="kind-misleading">misleading</span> (a confident pose, off by more than ε_safe)'
    if case.kind == BreachKind.FLAGGED.value:
        return '<span class="kind-flagged">flagged only</span> (the system knows it has no fix)'
    return "unknown (the row's points are not stored)"


def _facts(ctx: Context, rank: int, case: WorstCase, picture: str, sample: Any = None) -> str:
    """The text of one entry: what, where, how bad; with the rebuilt ``sample``, each corner's shift in pixels
    and what a pixel is worth."""
    outcome = ("unknown" if case.reason is None else "a confident pose" if not case.reason
               else f"no pose: <code>{esc(case.reason)}</code> (counted as the {ctx.spec.settings.penalty_m:g} m penalty)")
    conf = "–" if case.conf is None else f"{case.conf:.2f} (τ_conf = {ctx.spec.settings.conf_threshold:g})"
    if case.corners is not None:
        corners = "drawn (red)"
    elif case.reason in NO_CANDIDATE:
        corners = "none (no candidate selected)"
    else:
        corners = "not stored (a row written before schema 4, or read off a longer run)"
    items = [("kind", _kind_text(case)), ("error at θ*", f"{fmt_num(case.worst_m)} m (ε_safe = {ctx.eps:g} m)"),
             ("unperturbed, L(0)", nominal_text(case, ctx.eps, ctx.spec.settings.conf_threshold)),
             ("θ*", esc(theta_text(case.theta) or "–")), ("the pipeline at θ*", outcome), ("confidence", conf),
             ("box", esc(case.box_label)),
             ("found by", esc(style(case.method)["label"]) + (f", {esc(case.budget_label)}" if case.budget_label
                                                               else "")),
             ("predicted corners", corners)]
    if sample is not None:
        shift = corner_shifts(None if case.corners is None else np.asarray(case.corners), true_after(case, sample))
        shift0 = corner_shifts(None if case.nominal_corners is None else np.asarray(case.nominal_corners),
                                 sample.corners_2d)
        items.append(("corner shift at θ*", esc(shifts_text(shift)) + " (predicted − true)"))
        items.append(("corner shift unperturbed", esc(shifts_text(shift0))))
        items.append(("what a pixel is worth", esc(geometry_text(sample))))
    if case.position_sigma_m is not None:  # a detector that says how sure it is
        monitor = ctx.spec.settings.monitor_sigma_m
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
        "circle is corner TR; order TR, TL, BL, BR) and the corners the detector predicted there (red crosses), "
        "its error L(0) in the title; right: the image perturbed at θ*, the search's worst point, with the true "
        "corners moved by the perturbation and the corners predicted there. Each picture is a crop scaled to the "
        "runway and drawn pixel by pixel (one block is one image pixel): far out, an error of a kilometre is a "
        "corner shift of one or two pixels, so each corner's shift is printed under it and beside it what a pixel "
        "is worth at that distance. An image already above ε_safe / 2 unperturbed is marked: there the "
        "perturbation did not break a sound pose. The images are rebuilt from the run's dataset source and "
        "perturbed at θ* here (the store holds θ*, the errors, the kind and the predicted corners).</p>")
    samples, why = _samples(ctx, [w.sample_id for w in ev.worst])
    if why:
        s.html.append(f'<p class="warn">No pictures: {esc(why)}.</p>')
    digests = ctx.store.image_digests() if samples else {}
    for rank, case in enumerate(ev.worst, start=1):
        sample, figure, note, drawn = samples.get(case.sample_id), "", "", None
        if sample is not None:
            note = _differs(ctx, sample, digests)
            if not note:
                try:
                    fig = case_figure(case, sample)
                    drawn = sample
                    figure = ctx.figure(fig, f"gallery_{rank:02d}", "", colors=GALLERY_COLORS)
                except Exception as exc:  # one image that cannot be drawn must not hide the others
                    logger.warning("gallery: %s %s not drawn: %s", unit, case.sample_id, exc)
                    plt.close("all")
                    note = f"its picture cannot be made here ({type(exc).__name__}: {exc})"
                finally:
                    sample.drop_pixels()
        elif samples:
            note = "not in the rebuilt dataset"
        facts = _facts(ctx, rank, case, note and f"not drawn: {note}", drawn)
        s.html.append(f'<div class="case">{figure}{facts}</div>')
    return s
