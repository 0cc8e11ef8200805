"""Runtime monitors: how many hazardously misleading poses a reprojection-residual monitor flags, and how many
nominal poses it rejects (``audit --monitor-residual PX``).

Misleading poses: every job of the paper run's spatial-2d experiment (roll × contrast, six boxes, 100 images, four
methods; shipped detector v9) whose search found a confident pose off by more than ε_safe — its worst such θ,
evaluated again (one per image and θ). Nominal poses: the unperturbed view of 300 synthetic approaches of seed 0
(the paper's 100 and 200 more) whose pose is within ε_safe. For each, the PnP reprojection residual (RMS, image
pixels) and the selected candidate's confidence. Measured: per residual limit, the share of misleading poses the
monitor flags and of nominal poses it rejects (exact 95 % intervals), and the AUROC of the residual (and of the
confidence) for "this pose is off by more than ε_safe".

Usage: ``python benchmarks/run_all.py --only monitors`` (≈ 2 min on one core).
"""

from __future__ import annotations

import lzma
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "results" / "paper" / "spatial-2d" / "results.sqlite.xz"
WORK = ROOT / "runs" / "bench_monitors"
LIMITS_PX = (0.5, 1.0, 2.0, 3.0, 5.0, 10.0)
NOMINAL = 300


def misleading_points(limit: int | None) -> list[tuple[str, object, np.ndarray]]:
    """(sample id, box, θ) of each misleading job's worst silent point, one per image and θ."""
    from vbl_robust.campaigns import ResultStore
    from vbl_robust.campaigns import metrics as mx
    from vbl_robust.campaigns.spec import CampaignSpec
    from vbl_robust.constants import BreachKind

    WORK.mkdir(parents=True, exist_ok=True)
    store = WORK / "spatial-2d.sqlite"
    if not store.exists():
        with lzma.open(PAPER) as src, open(store, "wb") as dst:
            shutil.copyfileobj(src, dst)
    out, seen = [], set()
    with ResultStore(store, readonly=True) as st:
        spec = CampaignSpec.from_dict(st.campaign()["spec"])
        for r in mx.main_rows(st, spec, with_trace=False):
            if mx.breach_kind(r, spec.eps_safe_m) is not BreachKind.MISLEADING:
                continue
            p = r.points
            silent = np.array([not c for c in p.reasons]) & np.isfinite(p.fs) & (p.fs > spec.eps_safe_m)
            i = int(np.flatnonzero(silent)[np.argmax(p.fs[silent])])
            key = (r.sample_id, tuple(np.round(p.xs[i], 9)))
            if key not in seen:
                seen.add(key)
                out.append((r.sample_id, r.box.box, p.xs[i]))
    return out[:limit] if limit else out


def measure(quick: bool) -> dict:
    import torch

    torch.set_num_threads(1)
    from vbl_robust.campaigns.work import Settings, build_objective
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes import generate
    from vbl_robust.space import ParameterBox

    det = DetectorSpec.shipped("default", {"engine": "onnxruntime"}).build()
    settings = Settings(1000.0, 5000.0, 0.25, "ippe_lm")
    n_nominal = 6 if quick else NOMINAL
    samples = {s.id: s for s in generate(max(n_nominal, 100), seed=0)}
    mis = {"residual": [], "conf": []}
    for sid, box, theta in misleading_points(4 if quick else None):
        rec = build_objective(samples[sid], det, box, settings).evaluate(theta[None])
        if rec.reason[0] == "" and rec.error_m[0] > settings.eps_safe_m:  # still misleading (deterministic)
            mis["residual"].append(float(rec.reproj_error_px[0]))
            mis["conf"].append(float(rec.conf[0]))
        samples[sid].drop_pixels()
    nom = {"residual": [], "conf": []}
    ident = ParameterBox({"roll_deg": (-1.0, 1.0)})
    for sid in list(samples)[:n_nominal]:
        rec = build_objective(samples[sid], det, ident, settings).evaluate(np.zeros((1, 1)))
        if rec.reason[0] == "" and rec.error_m[0] <= settings.eps_safe_m:
            nom["residual"].append(float(rec.reproj_error_px[0]))
            nom["conf"].append(float(rec.conf[0]))
        samples[sid].drop_pixels()
    return {"misleading": mis, "nominal": nom}


def table(m: dict) -> str:
    from scipy.stats import mannwhitneyu

    from vbl_robust.stats import Rate

    mis, nom = (np.asarray(m[k]["residual"]) for k in ("misleading", "nominal"))
    mis_c, nom_c = (np.asarray(m[k]["conf"]) for k in ("misleading", "nominal"))
    lines = [f"Misleading poses: {len(mis)} (the worst silent θ of each spatial-2d job that found one); nominal poses: "
             f"{len(nom)} (unperturbed views within ε_safe). Residual = RMS reprojection error of the PnP pose "
             "(pixels of the 1024 × 1024 image).", "",
             f"Median residual: misleading {np.median(mis):.2f} px, nominal {np.median(nom):.2f} px. Median "
             f"confidence: misleading {np.median(mis_c):.2f}, nominal {np.median(nom_c):.2f}.", ""]
    if len(mis) and len(nom):
        auc = mannwhitneyu(mis, nom).statistic / (len(mis) * len(nom))
        auc_c = mannwhitneyu(-mis_c, -nom_c).statistic / (len(mis) * len(nom))
        lines += [f"AUROC for 'off by more than ε_safe': residual {auc:.3f}, (low) confidence {auc_c:.3f} "
                  "(0.5 = no better than chance).", ""]
    lines += ["| residual limit (px) | misleading flagged % [95 % CI] | nominal rejected % [95 % CI] |", "|---|---|---|"]
    for lim in LIMITS_PX:
        lines.append(f"| {lim:g} | {Rate(int((mis > lim).sum()), len(mis)).text(1, percent=False)} | "
                     f"{Rate(int((nom > lim).sum()), len(nom)).text(1, percent=False)} |")
    lines += ["", "Goal (issue 49's monitor): flag ≥ 80 % of misleading poses while rejecting ≤ 2 % of nominal ones."]
    return "\n".join(lines)


def main(quick: bool = False) -> str:
    return "## Runtime monitors: reprojection residual\n\n" + table(measure(quick)) + "\n"


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
