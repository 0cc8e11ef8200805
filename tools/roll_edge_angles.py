"""One-off (issue 29): does the detector's bias toward level threshold edges explain the roll breaches?

On the before/after audit's 50 images (seed 0), each turned by roll 0, ±5, ±10, ±15° (the audit's perturbation,
exact corner labels): per envelope and |roll|, the slope of the predicted on the true near-threshold angle, and the
survival of single rolled views with the predicted corners and with the same corners turned to the true edge angles
(each threshold edge rotated about its predicted midpoint, its predicted width kept), PnP ippe_lm.
    python tools/roll_edge_angles.py [--models default,hardened]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from vbl_robust.campaigns import load_samples
from vbl_robust.detect.harden import perturbed_sample, trainable
from vbl_robust.detect.shipped import default_detector
from vbl_robust.perturb import Perturbation
from vbl_robust.pnp import solve

EDGES = ((1, 0), (2, 3))  # keypoints TR, TL, BL, BR: far threshold TL→TR, near threshold BL→BR
ROLLS = (0, 5, -5, 10, -10, 15, -15)


def true_angles(k: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Predicted corners ``k`` with each threshold edge turned to the angle of the true one ``t``."""
    k = k.copy()
    for a, b in EDGES:
        mid, w = (k[a] + k[b]) / 2, np.linalg.norm(k[b] - k[a])
        d = (t[b] - t[a]) / np.linalg.norm(t[b] - t[a])
        k[a], k[b] = mid - d * w / 2, mid + d * w / 2
    return k


def angle(k: np.ndarray) -> float:
    d = k[3] - k[2]
    return float(np.degrees(np.arctan2(d[1], d[0])))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--models", default="default,hardened")
    args = ap.parse_args()
    torch.set_num_threads(1)
    samples, _ = load_samples(50, 0, lard=None, width=1024, height=1024)
    p = Perturbation(["roll_deg"])
    views = [(s.meta.get("envelope"), abs(r), perturbed_sample(s, p, np.array([float(r)]))) for s in samples
             for r in ROLLS if trainable(s, p, np.array([[float(r)]]))[0]]
    print("| model | envelope | near-edge angle slope | |roll| | views | survival, predicted | with true edge angles |")
    print("|---|---|---|---|---|---|---|")
    for model in args.models.split(","):
        det = default_detector(model=model)
        rows = []
        for env, r, v in views:
            img = torch.from_numpy(v.image).permute(2, 0, 1)[None].float() / 255.0
            d = det.detect(img)[0]
            if len(d.conf) == 0 or float(d.conf[0]) < 0.25:
                rows.append((env, r, np.nan, np.nan, 5000.0, 5000.0))
                continue
            k, t = np.asarray(d.keypoints[0], dtype=np.float64), v.corners_2d
            errs = []
            for c in (k, true_angles(k, t)):
                e = float(np.linalg.norm(solve(c[None], v.corners_3d, v.K, method="ippe_lm").position[0] - v.position))
                errs.append(e if np.isfinite(e) else 5000.0)
            rows.append((env, r, angle(t), angle(k), *errs))
        for env in ("far", "medium", "close"):
            a = np.array([x[1:] for x in rows if x[0] == env], dtype=np.float64)
            ok = np.isfinite(a[:, 1])
            slope = np.polyfit(a[ok, 1], a[ok, 2], 1)[0]
            for r in (0, 5, 10, 15):
                m = a[:, 0] == r
                print(f"| {model} | {env} | {slope:.2f} | {r}° | {m.sum()} | {100 * np.mean(a[m, 3] <= 1000):.1f} % "
                      f"| {100 * np.mean(a[m, 4] <= 1000):.1f} % |")


if __name__ == "__main__":
    main()
