"""Accuracy of a runway-corner detector on samples with known geometry (no perturbation).

Per sample: top candidate (σ_select at ``conf_threshold``), corner errors in **1024-px image units** (pixel
error × 1024 / image width), PnP position error for each solver, slant distance. :func:`summarize` aggregates
per envelope (``sample.meta["envelope"]``) and overall; a failure (no detection, PnP failure) counts as an
infinite position error, so medians and survival rates are over *all* samples.

*Detection* is the paper's criterion (a candidate with confidence ≥ τ_conf), whether or not it is on the
runway; *correct* detection adds a localisation criterion in the spirit of PCK: the mean corner error is at most
``PCK_FRACTION`` × the diagonal of the true corner box (so a far runway of 10 px must be hit within 2.5 px, a
close one within tens of pixels).

*Edge tilt* (:func:`edge_tilt_slope`): the slope of the predicted on the true angle of the runway's two
threshold edges (TL→TR, BL→BR) over correct detections. 1 is a detector that reads the edges' orientation; 0 one
that draws them level whatever the camera roll. Up to v7 every model had 0.2–0.35 (session 10); the angles
themselves barely move the PnP position (the model card's *What decides far survival*: the threshold widths do).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ..constants import CONF_THRESHOLD
from ..data.sample import Sample
from ..perturb.views import to_tensor
from ..stats import Paired, paired
from .base import DetectContext, select

#: nominal survival: position error ≤ this many metres with no perturbation
SURVIVAL_M = 1000.0

#: a detection is *correct* when its mean corner error ≤ this fraction of the true corner box's diagonal
PCK_FRACTION = 0.25


@dataclass
class EvalResult:
    """Per-sample results (N samples).

    envelope (N,) str; detected (N,) bool; conf (N,); corner_err (N, 4) 1024-px units (NaN if not detected);
    corner_delta (N, 4, 2) signed errors (predicted − true), 1024-px units; slant_m (N,);
    pos_err_m: solver → (N,) metres (inf on failure); box_diag (N,) diagonal of the true corner box,
    1024-px units; corners (N, 4, 2) true corners TR, TL, BL, BR, 1024-px units (None: not recorded).
    """

    envelope: np.ndarray
    detected: np.ndarray
    conf: np.ndarray
    corner_err: np.ndarray
    corner_delta: np.ndarray
    slant_m: np.ndarray
    pos_err_m: dict[str, np.ndarray]
    box_diag: np.ndarray
    corners: np.ndarray | None = None

    @property
    def correct(self) -> np.ndarray:
        """(N,) bool: detected and mean corner error ≤ ``PCK_FRACTION`` × true box diagonal."""
        return self.detected & (self.corner_err.mean(axis=1) <= PCK_FRACTION * self.box_diag)  # NaN → False


def evaluate_detector(
    detector, samples: Sequence[Sample], *, conf_threshold: float = CONF_THRESHOLD,
    pnp_methods: Sequence[str] = ("ippe_lm", "iterative"), batch: int = 8, drop_pixels: bool = True,
) -> EvalResult:
    """Run ``detector.detect`` on every sample (batches of same-size images) and score it."""
    from ..pnp.solvers import solve

    n = len(samples)
    delta = np.full((n, 4, 2), np.nan)
    conf = np.full(n, np.nan)
    ok = np.zeros(n, bool)
    i = 0
    while i < n:
        j = i + 1
        while j < n and j - i < batch and (samples[j].height, samples[j].width) == (samples[i].height,
                                                                                    samples[i].width):
            j += 1
        x = torch.cat([to_tensor(s.image) for s in samples[i:j]], 0)
        with torch.no_grad():
            sel = select(detector.detect(DetectContext.of_images(x)), conf_threshold)
        for k, s in enumerate(samples[i:j]):
            conf[i + k] = sel.conf[k]
            ok[i + k] = sel.ok[k]
            if sel.ok[k]:
                delta[i + k] = (sel.keypoints[k] - s.corners_2d) * (1024.0 / s.width)
            if drop_pixels:
                s.drop_pixels()
        i = j
    pos = {}
    for m in pnp_methods:
        e = np.full(n, np.inf)
        for k, s in enumerate(samples):
            if not ok[k]:
                continue
            kp = s.corners_2d + delta[k] * (s.width / 1024.0)
            r = solve(kp[None], s.corners_3d, s.K, method=m)
            if bool(r.success[0]) and np.all(np.isfinite(r.position[0])):
                e[k] = float(np.linalg.norm(r.position[0] - s.position))
        pos[m] = e
    return EvalResult(
        envelope=np.array([str(s.meta.get("envelope", "all")) for s in samples]),
        detected=ok, conf=conf, corner_err=np.linalg.norm(delta, axis=-1), corner_delta=delta,
        slant_m=np.array([s.slant_distance_m for s in samples]), pos_err_m=pos,
        box_diag=np.array([np.linalg.norm(np.ptp(s.corners_2d, axis=0)) * 1024.0 / s.width for s in samples]),
        corners=np.array([s.corners_2d * 1024.0 / s.width for s in samples]).reshape(n, 4, 2),
    )


def edge_angles_deg(corners: np.ndarray) -> np.ndarray:
    """(..., 4, 2) corners TR, TL, BL, BR → (...) mean angle (degrees) of the edges TL→TR and BL→BR."""
    c = np.asarray(corners, float)
    top, bottom = c[..., 0, :] - c[..., 1, :], c[..., 3, :] - c[..., 2, :]
    return np.degrees((np.arctan2(top[..., 1], top[..., 0]) + np.arctan2(bottom[..., 1], bottom[..., 0])) / 2)


def edge_tilt_slope(r: EvalResult, mask: np.ndarray | None = None) -> float:
    """Least-squares slope of predicted on true threshold-edge angle over the correct detections in ``mask``.

    NaN when fewer than 3 such detections, when their true angles do not vary, or when ``r`` has no corners.
    """
    if r.corners is None:
        return float("nan")
    m = r.correct & (np.ones(len(r.envelope), bool) if mask is None else mask)
    if m.sum() < 3:
        return float("nan")
    t = edge_angles_deg(r.corners[m])
    p = edge_angles_deg(r.corners[m] + r.corner_delta[m])
    ok = np.isfinite(t) & np.isfinite(p)
    t, p = t[ok], p[ok]
    if t.size < 3 or np.ptp(t) == 0:
        return float("nan")
    tc = t - t.mean()
    return float(np.dot(tc, p - p.mean()) / np.dot(tc, tc))


def range_rows(r: EvalResult, groups: Sequence[str] = ("far", "medium", "close")) -> list[dict]:
    """Rows per envelope present in ``groups`` order, then ``"all"``: counts, rates, medians, percentiles."""
    rows = []
    names = [g for g in groups if np.any(r.envelope == g)] + ["all"]
    for g in names:
        m = np.ones(len(r.envelope), bool) if g == "all" else r.envelope == g
        ce = r.corner_err[m][r.detected[m]].ravel()
        dl = r.corner_delta[m][r.detected[m]].reshape(-1, 2)
        row = dict(envelope=g, n=int(m.sum()), detection_rate=float(r.detected[m].mean()) if m.any() else np.nan,
                   correct_rate=float(r.correct[m].mean()) if m.any() else np.nan,
                   corner_median_px=float(np.median(ce)) if ce.size else np.nan,
                   corner_p95_px=float(np.percentile(ce, 95)) if ce.size else np.nan,
                   bias_u_px=float(dl[:, 0].mean()) if dl.size else np.nan,
                   bias_v_px=float(dl[:, 1].mean()) if dl.size else np.nan,
                   edge_tilt_slope=edge_tilt_slope(r, m))
        for meth, e in r.pos_err_m.items():
            em = e[m]
            row[f"survival_{meth}"] = float(np.mean(em <= SURVIVAL_M)) if m.any() else np.nan
            row[f"pos_err_pct_{meth}"] = float(np.median(100.0 * em / r.slant_m[m])) if m.any() else np.nan
        rows.append(row)
    return rows


def comparison_key(r: EvalResult, method: str = "ippe_lm") -> tuple[float, float]:
    """Model-comparison key (higher is better): (nominal survival, − median position error % of slant)."""
    e = r.pos_err_m[method]
    return float(np.mean(e <= SURVIVAL_M)), -float(np.median(100.0 * e / r.slant_m))


def paired_seeds(new: dict, old: dict, split: str = "validation") -> tuple[list[tuple[str, Paired]], Paired]:
    """Per seed and pooled :func:`vbl_robust.stats.paired` (exact McNemar) of two protocol results (``benchmarks/detector_protocol.py
    --json``: ``split`` → seed → summary rows, ``survived`` → seed → each approach's survival) on the seeds of
    ``split`` that both hold. Raises ValueError saying what is missing."""
    seeds = [s for s in new.get(split, {}) if s in old.get(split, {})]
    if not seeds:
        raise ValueError(f"no {split} seed in both protocol results")
    for name, p in (("new", new), ("old", old)):
        if any(s not in p.get("survived", {}) for s in seeds):
            raise ValueError(f"the {name} protocol results have no per-approach results (written before they were "
                             "recorded: rerun benchmarks/detector_protocol.py --json)")
    rows = [(s, paired(new["survived"][s], old["survived"][s])) for s in seeds]
    pooled = paired(sum((new["survived"][s] for s in seeds), []), sum((old["survived"][s] for s in seeds), []))
    return rows, pooled
