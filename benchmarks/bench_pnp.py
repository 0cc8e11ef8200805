"""PnP accuracy on synthetic LARD V2 approaches, gradient fidelity and cost of the differentiable layer.

Approaches come from :func:`vbl_robust.scenes.sample_approaches` (LARD V2 Far / Medium / Close envelopes,
runways 1500–4000 × 30–60 m, whole runway in the 1024 × 1024, 60° image). The exact projected corners get
Gaussian noise of σ = 0, 0.5 and 2 px (the same noisy corners for every solver), and each solver's camera
position is compared with the true one.

Run: ``python benchmarks/bench_pnp.py`` (reference sizes) or ``python benchmarks/bench_pnp.py --quick``;
``--batched`` runs only the section comparing the vectorised ``ippe_lm`` with the row-wise one it replaced.
"""

from __future__ import annotations

import sys
import time

import cv2
import numpy as np
import torch

from vbl_robust.geometry.camera import intrinsics, project
from vbl_robust.pnp.differentiable import pnp_position_torch, position_jacobian_fd
from vbl_robust.pnp.solvers import ROWWISE, SOLVERS, solve
from vbl_robust.scenes.envelopes import sample_approaches

ENVELOPES = ("far", "medium", "close")
NOISE_PX = (0.0, 0.5, 2.0)
FAIL_M = 1000.0
TEXTBOOK = "ippe→lm (lower first)"
BATCHES = (1, 32, 256)


def _textbook_ippe_lm(x: np.ndarray, Z: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The recipe as usually written: keep the lower IPPE solution, then OpenCV LM (no polish)."""
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(Z, x, K, None, flags=cv2.SOLVEPNP_IPPE)
    i = int(np.argmin(np.asarray(errs).ravel()[:n]))
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-12)
    r, t = cv2.solvePnPRefineLM(Z, x, K, None, rvecs[i].copy(), tvecs[i].copy(), crit)
    return -cv2.Rodrigues(r)[0].T @ t.ravel()


def _accuracy(n_per_env: int, seed: int) -> tuple[str, dict]:
    K = intrinsics()
    methods = (*SOLVERS, TEXTBOOK)
    errors: dict[tuple[str, float, str], list[float]] = {}
    rel: dict[tuple[str, float, str], list[float]] = {}
    for e_idx, env in enumerate(ENVELOPES):
        approaches = sample_approaches(n_per_env, seed=seed + e_idx, envelopes=(env,))
        rng = np.random.default_rng([seed, e_idx])
        for app in approaches:
            Z = app.corners_3d
            exact = project(Z, app.R, app.position, K)
            slant = app.slant_distance_m
            for sigma in NOISE_PX:
                x = exact + rng.normal(0.0, sigma, size=exact.shape) if sigma > 0 else exact
                for m in methods:
                    if m == TEXTBOOK:
                        pos = _textbook_ippe_lm(x, Z, K)
                    else:
                        res = solve(x, Z, K, method=m)
                        pos = res.position[0]
                    err = float(np.linalg.norm(pos - app.position)) if np.all(np.isfinite(pos)) else np.inf
                    for key_env in (env, "all"):
                        errors.setdefault((key_env, sigma, m), []).append(err)
                        rel.setdefault((key_env, sigma, m), []).append(100.0 * err / slant)
    lines = [
        "| σ (px) | envelope | solver | median (m) | p95 (m) | max (m) | failure rate | median % of slant |",
        "|---|---|---|---|---|---|---|---|",
    ]
    summary = {}
    for sigma in NOISE_PX:
        for env in (*ENVELOPES, "all"):
            for m in methods:
                e = np.asarray(errors[(env, sigma, m)])
                fail = np.mean(~(e <= FAIL_M))
                with np.errstate(invalid="ignore"):  # percentiles between infinite errors
                    med, p95, mx = np.median(e), np.percentile(e, 95), np.max(e)
                rmed = np.median(rel[(env, sigma, m)])
                summary[(env, sigma, m)] = (med, fail)
                lines.append(
                    f"| {sigma:g} | {env} | {m} | {_fmt(med)} | {_fmt(p95)} | {_fmt(mx)} | {100 * fail:.1f} % "
                    f"| {rmed:.3g} % |"
                )
    return "\n".join(lines) + "\n", summary


def _one_runway_batch(seed: int, n: int = 32) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Corners, K and (n, 4, 2) noisy corners (σ = 0.5 px) of n approaches, all to the first one's runway."""
    K = intrinsics()
    approaches = sample_approaches(n, seed=seed)
    Z = approaches[0].corners_3d
    rng = np.random.default_rng(seed)
    pts = np.stack([project(Z, a.R, a.position, K) for a in approaches]) + rng.normal(0.0, 0.5, size=(n, 4, 2))
    return Z, K, pts


def _solver_timing(reps: int, seed: int) -> str:
    """Wall time per row of ``solve`` with one row per call and with 32 rows per call (same runway)."""
    Z, K, pts = _one_runway_batch(seed + 300)
    lines = ["| solver | µs per row, 1 row per call | µs per row, 32 rows per call |", "|---|---|---|"]
    for m in (*SOLVERS, TEXTBOOK):
        single, batch = [], []
        for _ in range(reps):
            t0 = time.perf_counter()
            for b in range(32):
                _textbook_ippe_lm(pts[b], Z, K) if m == TEXTBOOK else solve(pts[b], Z, K, method=m)
            single.append((time.perf_counter() - t0) / 32)
            if m != TEXTBOOK:
                t0 = time.perf_counter()
                solve(pts, Z, K, method=m)
                batch.append((time.perf_counter() - t0) / 32)
        b_txt = f"{1e6 * np.median(batch):.0f}" if batch else "—"
        lines.append(f"| {m} | {1e6 * np.median(single):.0f} | {b_txt} |")
    return "\n".join(lines) + "\n"


def _batched_timing(reps: int, seed: int) -> tuple[str, dict[int, float]]:
    """Rows/s of ``ippe_lm`` (vectorised) and ``ippe_lm_rowwise`` (the implementation it replaced) on the same
    256 rows, solved in calls of 1, 32 or 256 rows; the two alternate run by run so both see the same load."""
    Z, K, pts = _one_runway_batch(seed + 400, n=max(BATCHES))
    methods = (ROWWISE, "ippe_lm")
    a, b = (solve(pts, Z, K, method=m) for m in methods)
    both = a.success & b.success
    diff = float(np.max(np.linalg.norm(a.position[both] - b.position[both], axis=1)))
    lines = ["| rows per call | row-wise rows/s | vectorised rows/s | ratio |", "|---|---|---|---|"]
    ratios = {}
    for B in BATCHES:
        calls = max(BATCHES) // B
        per_row: dict[str, list[float]] = {m: [] for m in methods}
        for _ in range(reps):
            for m in methods:
                t0 = time.perf_counter()
                for c in range(calls):
                    solve(pts[c * B:(c + 1) * B], Z, K, method=m)
                per_row[m].append((time.perf_counter() - t0) / (calls * B))
        old, new = (1.0 / np.median(per_row[m]) for m in methods)
        ratios[B] = new / old
        lines.append(f"| {B} | {old:,.0f} | {new:,.0f} | {new / old:.1f}× |")
    note = (f"Same {len(pts)} rows (σ = 0.5 px) for both; largest position difference between the two on them: "
            f"{diff:.1e} m; success flags {'identical' if np.array_equal(a.success, b.success) else 'DIFFER'}.\n")
    return "\n".join(lines) + "\n\n" + note, ratios


def batched_section(quick: bool = False) -> str:
    """The vectorised-vs-row-wise comparison alone (``--batched``)."""
    reps = 3 if quick else 15
    table, _ = _batched_timing(reps, 0)
    return f"""### Vectorised `ippe_lm` vs the row-wise implementation it replaced

Command: `python benchmarks/bench_pnp.py --batched{" --quick" if quick else ""}` (median of {reps} alternating runs,
1 torch thread). `ippe_lm_rowwise` = OpenCV IPPE per row + `refine.refine_lm`; `ippe_lm` = batched IPPE
(`pnp/ippe.py`) + `refine.refine_candidates`, all rows at once.

{table}"""


def _fmt(v: float) -> str:
    if not np.isfinite(v):
        return "∞"
    return f"{v:.3g}" if v < 1000 else f"{v:,.0f}"


def _jacobian(x: np.ndarray, Z: np.ndarray, K: np.ndarray, grad: str) -> np.ndarray:
    xt = torch.tensor(x[None], requires_grad=True)
    pos, _ = pnp_position_torch(xt, Z, K, grad=grad)
    return np.stack([torch.autograd.grad(pos[0, i], xt, retain_graph=True)[0].numpy().ravel() for i in range(3)])


def _gradient_fidelity(n_per_env: int, seed: int) -> str:
    K = intrinsics()
    lines = [
        "| envelope | poses | exact: median rel. error | exact: max | bpnp: median rel. error | bpnp: max |",
        "|---|---|---|---|---|---|",
    ]
    for e_idx, env in enumerate(ENVELOPES):
        rng = np.random.default_rng([seed, 100 + e_idx])
        ex, bp = [], []
        for app in sample_approaches(n_per_env, seed=seed + 100 + e_idx, envelopes=(env,)):
            Z = app.corners_3d
            x = project(Z, app.R, app.position, K) + rng.normal(0.0, 0.5, size=(4, 2))
            fd = position_jacobian_fd(x, Z, K)
            nrm = np.linalg.norm(fd)
            ex.append(np.linalg.norm(_jacobian(x, Z, K, "exact") - fd) / nrm)
            bp.append(np.linalg.norm(_jacobian(x, Z, K, "bpnp") - fd) / nrm)
        lines.append(
            f"| {env} | {len(ex)} | {np.median(ex):.1e} | {np.max(ex):.1e} | {np.median(bp):.1%} | {np.max(bp):.1%} |"
        )
    return "\n".join(lines) + "\n"


def _layer_timing(reps: int, seed: int) -> str:
    Z, K, pts = _one_runway_batch(seed + 200)
    lines = [
        "| batch | forward (ms) | backward exact (ms) | backward bpnp (ms) | forward per row (ms) |",
        "|---|---|---|---|---|",
    ]
    for B in (1, 8, 32):
        row = {}
        for grad in ("exact", "bpnp"):
            fw, bw = [], []
            for rep in range(reps + 1):  # first repetition = warm-up of torch.func
                xt = torch.tensor(pts[:B], requires_grad=True)
                t0 = time.perf_counter()
                pos, ok = pnp_position_torch(xt, Z, K, grad=grad)
                t1 = time.perf_counter()
                pos.sum().backward()
                t2 = time.perf_counter()
                if rep:
                    fw.append(t1 - t0)
                    bw.append(t2 - t1)
            row[grad] = (np.median(fw) * 1e3, np.median(bw) * 1e3)
        f = row["exact"][0]
        lines.append(f"| {B} | {f:.1f} | {row['exact'][1]:.1f} | {row['bpnp'][1]:.1f} | {f / B:.2f} |")
    return "\n".join(lines) + "\n"


def main(quick: bool = False) -> str:
    torch.set_num_threads(1)
    seed = 0
    n_env = 60 if quick else 500
    n_grad = 4 if quick else 30
    reps = 3 if quick else 15
    cmd = "python benchmarks/bench_pnp.py" + (" --quick" if quick else "")
    acc, summary = _accuracy(n_env, seed)
    fid = _gradient_fidelity(n_grad, seed)
    tim = _layer_timing(reps, seed)
    stim = _solver_timing(reps, seed)
    btab, _ = _batched_timing(reps, seed)

    def ratio(sigma: float) -> str:
        it, best = summary[("all", sigma, "iterative")], summary[("all", sigma, "ippe_lm")]
        return (f"σ = {sigma:g} px: failure rate ITERATIVE {100 * it[1]:.1f} % vs IPPE+LM {100 * best[1]:.1f} %, "
                f"median error {it[0]:.3g} m vs {best[0]:.3g} m")

    return f"""## PnP solvers: accuracy on LARD V2 approaches, gradient fidelity, layer cost

Command: `{cmd}` ({3 * n_env} approaches: {n_env} per LARD V2 envelope from `vbl_robust.scenes.sample_approaches`,
seed {seed}; 1024 × 1024 px, 60° FOV; Gaussian noise on the four exact corner projections, the same noisy corners
for every solver). Failure = no solution or position error > {FAIL_M:.0f} m. `{TEXTBOOK}` is the textbook recipe
(keep the lower IPPE solution, then `cv2.solvePnPRefineLM`) measured side by side with the package's `ippe_lm`
(both IPPE solutions refined by the package's batched Levenberg–Marquardt to the stationary point).

{acc}
Side by side (all envelopes): {ratio(0.5)}; {ratio(2.0)}.

### Gradient of the differentiable layer vs central finite differences of the converged solver

Relative Frobenius error of d(position)/d(corners) (3 × 8), σ = 0.5 px corner noise; `exact` = implicit gradient of
the reprojection objective, `bpnp` = BPnP's depth-weighted constraint (without BPnP's unit-norm rescaling).

{fid}
### Cost (wall clock, CPU, 1 torch thread; median of {reps} runs; the machine is shared, compare within a table)

`solve` per row:

{stim}
Differentiable layer (`pnp_position_torch`, forward = `ippe_lm`; after a warm-up of `torch.func`):

{tim}
Vectorised `ippe_lm` vs the row-wise implementation it replaced (`ippe_lm_rowwise`: OpenCV IPPE per row +
`refine.refine_lm`), rows/s on the same 256 rows in calls of 1, 32 and 256 rows, alternating runs:

{btab}"""


if __name__ == "__main__":
    torch.set_num_threads(1)
    quick = "--quick" in sys.argv
    print(batched_section(quick) if "--batched" in sys.argv else main(quick))
