"""Runtime monitors: how many hazardously misleading poses a monitor flags, and how many nominal poses it rejects
(``audit --monitor-residual PX``, ``audit --monitor-sigma M``).

**Reprojection residual** (any detector; here the shipped v9):
Misleading poses: every job of the paper run's spatial-2d experiment (roll × contrast, six boxes, 100 images, four
methods; shipped detector v9) whose search found a confident pose off by more than ε_safe — its worst such θ,
evaluated again (one per image and θ). Nominal poses: the unperturbed view of 300 synthetic approaches of seed 0
(the paper's 100 and 200 more) whose pose is within ε_safe. For each, the PnP reprojection residual (RMS, image
pixels) and the selected candidate's confidence. Measured: per residual limit, the share of misleading poses the
monitor flags and of nominal poses it rejects (exact 95 % intervals), and the AUROC of the residual (and of the
confidence) for "this pose is off by more than ε_safe".

**Corner σ** (a detector that says how sure it is: the YOLO26-pose pass-2 network of issue 49, behind v9's pass 1;
``SIGMA_MODEL``): each confident pose's corners' σ propagated through PnP to the position (metres,
:func:`vbl_robust.pnp.differentiable.position_sigma`). The limit is chosen on validation only — the 98th percentile of the σ of
the nominal poses (unperturbed, within ε_safe) of protocol seed 20261202 (510 approaches; aimed at rejecting ≤ 2 %)
— and then applied to the test views: the audit's images (``generate(100, seed=0)``, the paper run's) on a grid of
roll ±15° × contrast [0.5, 2] (7 × 5 views each, the unperturbed view among them). Measured there: the share of
misleading poses (confident, off by more than ε_safe) flagged and of nominal poses rejected (exact intervals), and
the AUROC for "this pose is off by more than ε_safe" of σ, of the residual and of the confidence over every
confident pose of the grid (bootstrap 95 % intervals over images). The same grid through v9 alone gives its
misleading count, paired per view (exact McNemar) against the candidate's with and without the monitor.

Usage: ``python benchmarks/run_all.py --only monitors`` (≈ 2 min on one core for the residual, ≈ 15 min for σ).
"""

from __future__ import annotations

import lzma
import os
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "results" / "paper" / "spatial-2d" / "results.sqlite.xz"
WORK = ROOT / "runs" / "bench_monitors"
LIMITS_PX = (0.5, 1.0, 2.0, 3.0, 5.0, 10.0)
NOMINAL = 300
#: the σ monitor's network (issue 49: step u2's last epoch, the best candidate; step u's in git history too).
#: Unshipped weights are not kept in the tree: restore them from git history (results/detector_candidates/README.md)
#: or pass another with ``$VBL_SIGMA_MODEL``.
SIGMA_MODEL = Path(os.environ.get("VBL_SIGMA_MODEL", ROOT / "results" / "detector_candidates" / "yolo26n_pass2_u2.pt"))
SIGMA_RESTORE = ("git show 306b97a:results/detector_candidates/yolo26n_pass2_u2.pt > "
                 "results/detector_candidates/yolo26n_pass2_u2.pt")
SIGMA_VALIDATION_SEED = 20261202
GRID = (np.linspace(-15.0, 15.0, 7), np.array([0.5, 0.7, 1.0, 1.4, 2.0]))
NOMINAL_QUANTILE = 0.98


def misleading_points(limit: int | None) -> list[tuple[str, object, np.ndarray]]:
    """(sample id, box, θ) of each misleading job's worst silent point, one per image and θ."""
    from vbl_robust.analysis.breach import breach_kind
    from vbl_robust.analysis.readoff import main_rows
    from vbl_robust.constants import BreachKind
    from vbl_robust.store.core import ResultStore

    WORK.mkdir(parents=True, exist_ok=True)
    store = WORK / "spatial-2d.sqlite"
    if not store.exists():
        with lzma.open(PAPER) as src, open(store, "wb") as dst:
            shutil.copyfileobj(src, dst)
    out, seen = [], set()
    with ResultStore(store, readonly=True) as st:
        spec = st.spec()
        for r in main_rows(st, spec, with_trace=False):
            if breach_kind(r, spec.settings.eps_safe_m) is not BreachKind.MISLEADING:
                continue
            p = r.points
            silent = np.array([not c for c in p.reasons]) & np.isfinite(p.fs) & (p.fs > spec.settings.eps_safe_m)
            i = int(np.flatnonzero(silent)[np.argmax(p.fs[silent])])
            key = (r.sample_id, tuple(np.round(p.xs[i], 9)))
            if key not in seen:
                seen.add(key)
                out.append((r.sample_id, r.box.box, p.xs[i]))
    return out[:limit] if limit else out


def measure(quick: bool) -> dict:
    import torch

    torch.set_num_threads(1)
    from vbl_robust.campaigns.work import build_objective
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.space import ParameterBox
    from vbl_robust.specs.settings import PipelineSettings

    det = DetectorSpec.shipped("default", {"engine": "onnxruntime"}).build()
    settings = PipelineSettings()
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


def grid_records(det, samples, settings) -> tuple[list, list, float]:
    """Every view of ``GRID`` (roll × contrast) of each sample through ``det``: one EvalRecord per sample, the
    positions PnP gives from the pass-1 corners of the same views (the two passes' disagreement is a monitor signal
    of its own), and the process-clock seconds of the objective's evaluations (pass 1 again not counted)."""
    import time

    import torch

    from vbl_robust.campaigns.work import build_objective
    from vbl_robust.pnp.solvers import solve
    from vbl_robust.space import ParameterBox

    box = ParameterBox({"roll_deg": (-15.0, 15.0), "contrast": (0.5, 2.0)})
    theta = np.array([(r, c) for r in GRID[0] for c in GRID[1]])
    recs, first, seconds = [], [], 0.0
    for s in samples:
        obj = build_objective(s, det, box, settings)
        obj.evaluate(theta[:1])  # pixels loaded outside the clock
        t0 = time.process_time()
        recs.append(obj.evaluate(theta))
        seconds += time.process_time() - t0
        with torch.no_grad():
            top = det.first.top(obj.context(theta))
        kp = obj.scale.to_original(top.keypoints.double().numpy())
        pos = np.full((len(theta), 3), np.nan)
        good = top.conf.numpy() >= settings.conf_threshold
        if good.any():
            res = solve(kp[good], s.corners_3d, s.K, method=settings.pnp)
            pos[good] = np.where(res.success[:, None], res.position, np.nan)
        first.append(pos)
        s.drop_pixels()
    return recs, first, seconds


def sigma_measure(quick: bool, model: Path = SIGMA_MODEL) -> dict:
    import torch

    torch.set_num_threads(1)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_detector import held_out
    from vbl_robust.campaigns.work import build_objective
    from vbl_robust.detect.shipped import default_detector
    from vbl_robust.detect.twostage import TwoStageDetector
    from vbl_robust.detect.ultralytics import UltralyticsDetector
    from vbl_robust.scenes.generate import generate
    from vbl_robust.space import ParameterBox
    from vbl_robust.specs.settings import PipelineSettings

    settings = PipelineSettings()
    v9 = default_detector()
    cand = TwoStageDetector(v9.first, UltralyticsDetector(model, trust=True, imgsz=320))
    ident = ParameterBox({"roll_deg": (-1.0, 1.0)})
    val, z = [], []  # σ of the nominal poses of the validation seed (the limit); corner error / corner σ
    for s in held_out(12 if quick else 510, SIGMA_VALIDATION_SEED):
        rec = build_objective(s, cand, ident, settings).evaluate(np.zeros((1, 1)))
        if rec.reason[0] == "" and rec.error_m[0] <= settings.eps_safe_m:
            val.append(float(rec.position_sigma_m[0]))
        if rec.reason[0] == "":
            z.extend((np.abs(rec.keypoints[0] - np.asarray(s.corners_2d)) / rec.keypoint_sigma[0]).ravel())
        s.drop_pixels()
    limit = float(np.quantile(val, NOMINAL_QUANTILE))
    samples = generate(4 if quick else 100, seed=0)
    out = {"limit_m": limit, "n_validation": len(val), "eps": settings.eps_safe_m, "z": np.array(z)}
    for name, det in (("cand", cand), ("v9", v9)):
        out[name], out[f"{name}_first"], out[f"{name}_s"] = grid_records(det, samples, settings)
    return out


def _auroc(score: np.ndarray, bad: np.ndarray, groups: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """AUROC of ``score`` for ``bad`` and a 95 % bootstrap interval over groups (images)."""
    from scipy.stats import mannwhitneyu

    def auc(idx):
        s, b = score[idx], bad[idx]
        if b.all() or not b.any():
            return np.nan
        return mannwhitneyu(s[b], s[~b]).statistic / (b.sum() * (~b).sum())

    ids = np.unique(groups)
    rows = {g: np.flatnonzero(groups == g) for g in ids}
    rng = np.random.default_rng(seed)
    boot = [auc(np.concatenate([rows[g] for g in rng.choice(ids, len(ids))])) for _ in range(1000)]
    lo, hi = np.nanpercentile(boot, [2.5, 97.5])
    return float(auc(np.arange(len(score)))), float(lo), float(hi)


def sigma_table(m: dict) -> str:
    from vbl_robust.stats import Rate, paired

    eps, limit = m["eps"], m["limit_m"]
    rows = []
    for k, (rc, rv, p1, q1) in enumerate(zip(m["cand"], m["v9"], m["cand_first"], m["v9_first"], strict=True)):
        for i in range(len(rc)):
            rows.append((k, rc.reason[i] == "", rc.error_m[i], rc.position_sigma_m[i], rc.reproj_error_px[i],
                         rc.conf[i], rc.theta[i, 0] == 0 and rc.theta[i, 1] == 1.0,
                         rv.reason[i] == "" and rv.error_m[i] > eps, rv.reason[i] == "", rv.error_m[i],
                         np.linalg.norm(rc.position[i] - p1[i]), np.linalg.norm(rv.position[i] - q1[i])))
    (img, ok, err, sig, res, conf, nominal, v9_mis, v9_ok, v9_err, gap,
     v9_gap) = (np.array(c) for c in zip(*rows, strict=True))
    mis = ok & (err > eps)
    good = ok & (err <= eps)
    flagged = sig > limit
    nom = good & nominal
    cand_mis_after = mis & ~flagged
    conf_rows = ok
    auc_s = _auroc(sig[conf_rows], mis[conf_rows], img[conf_rows])
    auc_r = _auroc(res[conf_rows], mis[conf_rows], img[conf_rows])
    auc_c = _auroc(-conf[conf_rows], mis[conf_rows], img[conf_rows])
    gap_rows = conf_rows & np.isfinite(gap)
    auc_g = _auroc(gap[gap_rows], mis[gap_rows], img[gap_rows])
    v9_rows = v9_ok & np.isfinite(v9_gap)
    auc_g9 = _auroc(v9_gap[v9_rows], (v9_err > eps)[v9_rows], img[v9_rows])
    n_views = len(ok)
    rate_c, rate_v = n_views / m["cand_s"], n_views / m["v9_s"]
    n_img = len(np.unique(img))
    t_raw = paired(mis, v9_mis)
    t_mon = paired(cand_mis_after, v9_mis)
    lines = [
        f"Limit {limit:.0f} m: the {NOMINAL_QUANTILE:.0%} quantile of the σ of {m['n_validation']} nominal poses "
        f"of validation seed {SIGMA_VALIDATION_SEED}. Test: {n_img} images × {len(GRID[0])} rolls × {len(GRID[1])} "
        f"contrasts = {len(ok)} views; {int(ok.sum())} confident poses, {int(mis.sum())} misleading (off by "
        f"more than ε_safe), {int(nom.sum())} nominal.", "",
        f"Calibration of the corner σ on the validation seed's unperturbed views ({len(m['z'])} coordinates): "
        f"median |error| / σ {np.median(m['z']):.2f}; within 1 σ {np.mean(m['z'] <= 1):.0%}, within 2 σ "
        f"{np.mean(m['z'] <= 2):.0%} (a Gaussian: 68 %, 95 %; σ is the scale of the learned error law of the "
        "residual log-likelihood loss, not a standard deviation).", "",
        "| monitor | misleading flagged % [95 % CI] | nominal rejected % [95 % CI] | good perturbed poses rejected % |",
        "|---|---|---|---|",
        f"| σ ≤ {limit:.0f} m | {Rate(int((mis & flagged).sum()), int(mis.sum())).text(1, percent=False)} | "
        f"{Rate(int((nom & flagged).sum()), int(nom.sum())).text(1, percent=False)} | "
        f"{Rate(int((good & flagged).sum()), int(good.sum())).text(1, percent=False)} |", "",
        f"AUROC for 'off by more than ε_safe' over the confident poses [95 % bootstrap over images]: σ "
        f"{auc_s[0]:.3f} [{auc_s[1]:.3f}, {auc_s[2]:.3f}], reprojection residual {auc_r[0]:.3f} [{auc_r[1]:.3f}, "
        f"{auc_r[2]:.3f}], low confidence {auc_c[0]:.3f} [{auc_c[1]:.3f}, {auc_c[2]:.3f}], the two passes' "
        f"disagreement (metres between the positions of pass 1's and pass 2's corners) {auc_g[0]:.3f} "
        f"[{auc_g[1]:.3f}, {auc_g[2]:.3f}] (0.5 = chance). The same disagreement for v9 on its own confident poses: "
        f"{auc_g9[0]:.3f} [{auc_g9[1]:.3f}, {auc_g9[2]:.3f}].", "",
        f"Throughput on these views (process clock, one thread, the objective's evaluations only): candidate "
        f"{rate_c:.1f} evaluations/s, v9 {rate_v:.1f} (v9 / candidate {rate_v / rate_c:.2f}; goal ≤ 1.2).", "",
        f"Misleading views, paired on the same {len(ok)} views against v9 (which has {int(v9_mis.sum())}): the "
        f"candidate without the monitor {int(mis.sum())} (only it {t_raw.only_a}, only v9 {t_raw.only_b}, exact "
        f"McNemar p = {t_raw.p_value:.3g}); with it {int(cand_mis_after.sum())} (only it {t_mon.only_a}, only v9 "
        f"{t_mon.only_b}, p = {t_mon.p_value:.3g}).",
        "", "Goal (issue 49's monitor): flag ≥ 80 % of misleading poses while rejecting ≤ 2 % of nominal ones."]
    return "\n".join(lines)


def main(quick: bool = False) -> str:
    from vbl_robust.digest import file_sha256

    if not SIGMA_MODEL.is_file():  # never drop the measured σ section silently
        raise SystemExit(f"bench_monitors: {SIGMA_MODEL} not found; restore it ({SIGMA_RESTORE}) or set "
                         "$VBL_SIGMA_MODEL")
    return ("## Runtime monitors: reprojection residual\n\n" + table(measure(quick)) + "\n"
            "\n## Runtime monitors: corner σ (YOLO26-pose pass 2 behind v9's pass 1)\n\n"
            f"Pass-2 network: `{_shown(SIGMA_MODEL)}` (SHA-256 {file_sha256(SIGMA_MODEL)[:12]}).\n\n"
            + sigma_table(sigma_measure(quick)) + "\n")


def _shown(path: Path) -> str:
    """``path`` relative to the repository when inside it (the section names the network it measured)."""
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


if __name__ == "__main__":
    print(main("--quick" in sys.argv))
