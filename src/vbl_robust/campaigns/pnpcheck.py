"""The PnP-solver comparison of one image (experiment ``pnp-validation``).

For the ground-truth corners (exact, and integer-truncated as LARD's labels are: what the paper's 2.2 % on
ground truth measures, our exact labels give ≈ 1e-12 %) and for the detector's corners on the unperturbed image,
every solver of
:data:`vbl_robust.pnp.solvers.SOLVERS` gives a camera position; the payload holds its absolute error (m) and its error
relative to the slant distance (%). The differentiable layer's forward pass *is* a solver (``ippe_lm``), so its
positions need no separate row; what differs between its ``exact`` and ``bpnp`` modes is the gradient, so the
payload also holds the cosine between their Jacobians ``dC/dx`` (3 × 8) at the detector's corners.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..constants import NotMeasured, NotMeasuredError

#: Keypoint source of the PnP comparison: the ground-truth corners truncated to integers as LARD labels them.
TRUNCATED = "truncated ground truth"


def _errors(kp: np.ndarray, sample: Any) -> dict[str, dict[str, float | None]]:
    from ..pnp.solvers import SOLVERS, solve

    out: dict[str, dict[str, float | None]] = {}
    dist = float(sample.slant_distance_m)
    for method in SOLVERS:
        res = solve(kp[None], sample.corners_3d, sample.K, method=method)
        if not bool(res.success[0]):
            out[method] = {"abs_m": None, "rel_pct": None, "reason": res.reason[0]}
            continue
        err = float(np.linalg.norm(res.position[0] - sample.position))
        out[method] = {"abs_m": err, "rel_pct": 100.0 * err / dist, "reason": ""}
    return out


def jacobian_cosine(kp: np.ndarray, sample: Any) -> float | None:
    """Cosine between the Jacobians dC/dx (3 × 8) of the differentiable PnP in "exact" and "bpnp" modes."""
    import torch

    from ..pnp.differentiable import GRAD_MODES, pnp_position_torch

    if "bpnp" not in GRAD_MODES:
        return None
    jac = {}
    for mode in ("exact", "bpnp"):
        rows = []
        for a in range(3):
            x = torch.tensor(kp[None], dtype=torch.float64, requires_grad=True)
            pos, ok = pnp_position_torch(x, sample.corners_3d, sample.K, grad=mode)
            if not bool(ok[0]):
                return None
            (g,) = torch.autograd.grad(pos[0, a], x)
            rows.append(g.reshape(-1).numpy())
        jac[mode] = np.concatenate(rows)
    a, b = jac["exact"], jac["bpnp"]
    den = float(np.linalg.norm(a) * np.linalg.norm(b))
    return None if den == 0 or not math.isfinite(den) else float(a @ b / den)


def pnp_comparison(sample: Any, detector: Any, settings: Any) -> dict[str, Any]:
    """Payload for one image: ``{"errors": {source: {solver: {abs_m, rel_pct, reason}}}, "detector": {...},
    "grad_cosine_bpnp_vs_exact": float | None}``; sources "ground truth", :data:`TRUNCATED` and "detector" (the
    latter absent when the detector finds no runway above τ_conf)."""
    from ..data.lard import truncated_labels
    from ..pipeline import Objective
    from ..space import ParameterBox

    objective = Objective(sample, detector, ParameterBox({"roll_deg": (-1.0, 1.0)}), pnp=settings.pnp,
                          conf_threshold=settings.conf_threshold, penalty_m=settings.penalty_m)
    if objective.image_error:
        raise NotMeasuredError(NotMeasured.INPUT_UNAVAILABLE, f"sample {sample.id}: {objective.image_error}")
    rec = objective.evaluate(np.zeros((1, 1)))
    kp = np.asarray(rec.keypoints[0], dtype=np.float64)
    truth = np.asarray(sample.corners_2d, dtype=np.float64)
    errors = {"ground truth": _errors(truth, sample), TRUNCATED: _errors(truncated_labels(truth), sample)}
    det_info = {"reason": rec.reason[0], "conf": None if not math.isfinite(rec.conf[0]) else float(rec.conf[0])}
    cosine = None
    if np.isfinite(kp).all():
        errors["detector"] = _errors(kp, sample)
        det_info["corner_error_px"] = float(np.median(np.linalg.norm(kp - sample.corners_2d, axis=1)))
        cosine = jacobian_cosine(kp, sample)
    return {"errors": errors, "detector": det_info, "grad_cosine_bpnp_vs_exact": cosine,
            "slant_distance_m": float(sample.slant_distance_m)}
