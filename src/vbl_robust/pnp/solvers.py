"""OpenCV PnP solvers for the four runway corners, batched, with failure flags instead of exceptions.

Conventions
-----------
* ``points_2d`` are float pixels in the OpenCV convention (``u`` right, ``v`` down, pixel centres at integers),
  in the corner order **TR, TL, BL, BR** of ``corners_3d`` (runway frame, metres; see
  :mod:`vbl_robust.geometry.camera`).
* OpenCV returns the world → camera pose ``(rvec, tvec)``: ``X_cv = R(rvec) X_rwy + tvec`` with OpenCV camera
  axes (X right, Y down, Z forward). The camera position in the runway frame is ``C = −R(rvec)ᵀ tvec``.
* ``reproj_error_px`` is the RMS over the four corners of the pixel distance between the reprojected corners
  and ``points_2d``: ``sqrt(mean_i ‖π_i − x_i‖²)``.

Solvers (``SOLVERS``)
---------------------
``"ippe_lm"`` (default)
    The two IPPE poses of the planar ambiguity (:func:`.ippe.ippe_poses`, all rows at once, hand-written NumPy
    because OpenCV has no batched IPPE) are both refined with Levenberg–Marquardt in float64 to the stationary
    point of the reprojection objective (:func:`.refine.refine_candidates`, all rows and candidates at once) and
    the one with the lower *final* reprojection error is kept. Two deliberate departures from the recipe
    "lower IPPE solution, then ``cv2.solvePnPRefineLM``": (1) OpenCV 5.0's LM ignores its termination criteria
    and stops 0.26–0.5 m short of the optimum at 6 km (the implicit gradient needs the true stationary point),
    and costs several IPPE solves; (2) keeping the lower IPPE solution *before* refinement ends in a worse
    local minimum for about 3 % of poses with 2 px corner noise (23 of 800 measured over 500–6000 m; none of
    800 with 0.5 px). ``benchmarks/bench_pnp.py`` measures the recipe side by side. Where a row has no finite IPPE
    pose, OpenCV's SQPNP pose is refined instead.
``"ippe_lm_rowwise"`` (not in ``SOLVERS``; the reference for tests and ``benchmarks/bench_pnp.py``)
    The previous implementation of ``"ippe_lm"``, row by row: OpenCV's ``SOLVEPNP_IPPE`` per row (SQPNP where it
    returns only NaN poses, as it does for some exact keypoint sets), then :func:`.refine.refine_lm`. Same
    objective, candidates and stopping rules; ``tests/pnp/test_ippe_batched.py`` compares the two (same
    success and reasons; same position within 1e-6 m except where ``refine_lm`` stops a few µm short of the
    stationary point, see :func:`.refine.refine_candidates`). ``"ippe_lm"`` also runs this path for a ``K``
    whose last row is not exactly (0, 0, 1) (``check_intrinsics`` accepts it within 1e-8).
``"ippe"``
    ``SOLVEPNP_IPPE``, lower-reprojection solution, no refinement.
``"iterative"``
    ``SOLVEPNP_ITERATIVE`` without an initial guess (as in the seed paper). On coplanar corners it starts from a
    homography decomposition and often converges to a wrong local minimum under noise: a *solver* failure.
``"sqpnp"``
    ``SOLVEPNP_SQPNP``.

Failures
--------
A row the solver cannot handle is a recorded failure (``success`` False, NaN position/pose/error and a short
``reason``), never an exception: non-finite keypoints, collinear or coincident keypoints, a row of the wrong
shape (ragged input), keypoints beyond :data:`MAX_COORD_PX`, an OpenCV error, no solution, a non-finite
solution, or a solution that puts a runway corner behind the camera. Only whole-call mistakes (shape of ``points_2d``, ``corners_3d``, ``K``, unknown
``method``) raise ``ValueError``.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import cv2
import numpy as np

from .ippe import ippe_poses
from .refine import matrix_to_rotvec, refine_candidates, refine_lm, residuals, rotvec_to_matrix

logger = logging.getLogger(__name__)

SOLVERS: tuple[str, ...] = ("ippe_lm", "iterative", "sqpnp", "ippe")

#: The row-by-row implementation of ``"ippe_lm"``, accepted by :func:`solve` but not listed in ``SOLVERS``.
ROWWISE = "ippe_lm_rowwise"

#: Three keypoints count as collinear when the triangle's height is below this fraction of its longest side.
COLLINEAR_TOL = 1e-6

#: Keypoints spread over less than this (pixels, largest distance from their mean) count as coincident.
MIN_SPREAD_PX = 1e-6

#: Keypoints farther than this from the origin (pixels) are rejected: no camera sees a runway there, and
#: OpenCV's arithmetic overflows long before float64 does.
MAX_COORD_PX = 1e8

_N_CORNERS = 4
_TRIPLES = np.array(list(itertools.combinations(range(_N_CORNERS), 3)))


@dataclass(frozen=True, eq=False)
class PnPResult:
    """Batched PnP result; row ``b`` belongs to ``points_2d[b]``.

    Attributes:
        position: (B, 3) float64 camera position ``C = −Rᵀ t`` in the runway frame, metres (NaN where failed).
        success: (B,) bool.
        reproj_error_px: (B,) RMS reprojection error, pixels (NaN where failed).
        rvec: (B, 3) OpenCV world → camera rotation vector (axis-angle, radians; NaN where failed).
        tvec: (B, 3) OpenCV world → camera translation, metres (NaN where failed).
        method: solver name.
        reason: B strings, ``""`` for a success, else why the row failed.
    """

    position: np.ndarray
    success: np.ndarray
    reproj_error_px: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    method: str
    reason: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.success.shape[0])


def _as_numpy(a: object) -> object:
    """Detach torch tensors (without importing torch); leave anything else alone."""
    if hasattr(a, "detach") and hasattr(a, "cpu"):
        return a.detach().cpu().numpy()  # type: ignore[attr-defined]
    return a


def check_corners_3d(corners_3d: object) -> np.ndarray:
    """``corners_3d`` as a (4, 3) float64 array; ``ValueError`` if malformed or degenerate."""
    z = np.asarray(_as_numpy(corners_3d), dtype=np.float64)
    if z.shape != (_N_CORNERS, 3):
        raise ValueError(f"corners_3d: expected shape (4, 3) (TR, TL, BL, BR), got {z.shape}")
    if not np.all(np.isfinite(z)):
        raise ValueError(f"corners_3d: must be finite, got {z.tolist()}")
    if _degenerate_rows(_plane_coords(z)[None])[0]:
        raise ValueError(f"corners_3d: three corners are collinear or coincide, got {z.tolist()}")
    return z


def _plane_coords(z: np.ndarray) -> np.ndarray:
    """(4, 2) coordinates of (nearly) coplanar points in their best-fit plane."""
    c = z - z.mean(axis=0)
    _, _, vt = np.linalg.svd(c)
    return c @ vt[:2].T


def check_intrinsics(K: object) -> np.ndarray:
    """``K`` as a (3, 3) float64 pinhole matrix; ``ValueError`` if malformed."""
    k = np.asarray(_as_numpy(K), dtype=np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"K: expected shape (3, 3), got {k.shape}")
    if not np.all(np.isfinite(k)) or k[0, 0] <= 0 or k[1, 1] <= 0 or not np.allclose(k[2], [0.0, 0.0, 1.0]):
        raise ValueError(f"K: need a finite pinhole matrix with fx, fy > 0 and last row (0, 0, 1), got {k.tolist()}")
    return k


def check_method(method: str) -> str:
    if method not in SOLVERS and method != ROWWISE:
        raise ValueError(f"method: unknown PnP solver {method!r}; choose from {SOLVERS}")
    return method


def _degenerate_rows(x: np.ndarray) -> np.ndarray:
    """(B,) True where some three of the 4 points of a finite (B, 4, 2) array are collinear or coincide."""
    c = x - x.mean(axis=1, keepdims=True)
    scale = np.max(np.linalg.norm(c, axis=2), axis=1)
    bad = ~(scale > MIN_SPREAD_PX)
    c = c / np.where(bad, 1.0, scale)[:, None, None]
    a, b, d = c[:, _TRIPLES[:, 0]], c[:, _TRIPLES[:, 1]], c[:, _TRIPLES[:, 2]]  # (B, 4 triples, 2)
    ab, ad, bd = b - a, d - a, d - b
    cross = np.abs(ab[..., 0] * ad[..., 1] - ab[..., 1] * ad[..., 0])
    longest_sq = np.maximum(np.maximum((ab * ab).sum(-1), (ad * ad).sum(-1)), (bd * bd).sum(-1))
    # height / longest side = cross / longest²; coincident points give cross = 0 as well
    return bad | np.any(~(cross > COLLINEAR_TOL * longest_sq), axis=1)


def _rows(points_2d: object) -> tuple[np.ndarray, list[str]]:
    """Points as (B, 4, 2) float64 (NaN rows for unusable ones) and the per-row failure reasons."""
    raw = _as_numpy(points_2d)
    try:
        x = np.asarray(raw, dtype=np.float64)
    except (ValueError, TypeError):
        x = None
    if x is not None and x.shape == (_N_CORNERS, 2):
        x = x[None]
    if x is not None and x.ndim == 3 and x.shape[1:] == (_N_CORNERS, 2):
        return x, [""] * x.shape[0]
    if isinstance(raw, list | tuple) and (x is None or x.ndim == 3):
        # ragged batch: judge each row on its own
        out = np.full((len(raw), _N_CORNERS, 2), np.nan)
        reasons = [""] * len(raw)
        for b, row in enumerate(raw):
            try:
                r = np.asarray(_as_numpy(row), dtype=np.float64)
            except (ValueError, TypeError) as e:
                reasons[b] = f"unusable keypoints ({type(e).__name__})"
                continue
            if r.shape != (_N_CORNERS, 2):
                reasons[b] = f"keypoints of shape {r.shape}, expected (4, 2)"
                continue
            out[b] = r
        return out, reasons
    shape = getattr(x, "shape", type(raw).__name__)
    raise ValueError(f"points_2d: expected shape (4, 2) or (B, 4, 2), got {shape}")


def _opencv_candidates(method: str, z: np.ndarray, x: np.ndarray, K: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pose candidates (rvec (3,), tvec (3,)) of one row from OpenCV; may raise ``cv2.error``."""
    if method in ("ippe", "ippe_lm", ROWWISE):
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(z, x, K, None, flags=cv2.SOLVEPNP_IPPE)
        cands = [(np.asarray(r, np.float64).reshape(3), np.asarray(t, np.float64).reshape(3))
                 for r, t in zip(rvecs[:n], tvecs[:n], strict=True)]
        if method == "ippe":
            order = np.argsort(np.asarray(errs, dtype=np.float64).ravel()[:n])
            return [cands[int(i)] for i in order[:1]]
        if not any(np.all(np.isfinite(r)) and np.all(np.isfinite(t)) for r, t in cands):
            # OpenCV's IPPE returns NaN poses for some exact (noise-free) keypoint sets, e.g. a straight-in
            # approach with a yaw offset; SQPNP is then the start point of the same LM refinement.
            ok, rvec, tvec = cv2.solvePnP(z, x, K, None, flags=cv2.SOLVEPNP_SQPNP)
            if ok:
                cands.append((np.asarray(rvec, np.float64).reshape(3), np.asarray(tvec, np.float64).reshape(3)))
        return cands
    flag = {"iterative": cv2.SOLVEPNP_ITERATIVE, "sqpnp": cv2.SOLVEPNP_SQPNP}[method]
    ok, rvec, tvec = cv2.solvePnP(z, x, K, None, flags=flag)
    return [(np.asarray(rvec, np.float64).reshape(3), np.asarray(tvec, np.float64).reshape(3))] if ok else []


def _pick_best(
    method: str, z: np.ndarray, x: np.ndarray, K: np.ndarray, owner: np.ndarray, rv: np.ndarray, tv: np.ndarray,
    reasons: list[str], rvec: np.ndarray, tvec: np.ndarray, err: np.ndarray, position: np.ndarray,
) -> None:
    """Refine (``ippe_lm``) and validate the candidates, and write each row's best one into the outputs."""
    finite = np.all(np.isfinite(rv), axis=1) & np.all(np.isfinite(tv), axis=1)
    R = rotvec_to_matrix(np.where(finite[:, None], rv, 0.0))
    xs = x[owner]
    refined = method in ("ippe_lm", ROWWISE)
    if refined:
        R, tv, _ = refine_lm(z, xs, K, R, np.where(finite[:, None], tv, 0.0), groups=owner)
        finite &= np.all(np.isfinite(tv), axis=1)
    Xc, _, r = residuals(z, xs, K, R, np.where(finite[:, None], tv, 0.0))
    rms = np.sqrt(np.mean(np.sum(r * r, axis=2), axis=1))
    in_front = np.all(Xc[..., 2] > 0, axis=1)
    valid = finite & in_front & np.isfinite(rms)
    for b in np.unique(owner):
        mine = np.flatnonzero(owner == b)
        ok = mine[valid[mine]]
        if ok.size == 0:
            reasons[b] = ("non-finite solution" if not finite[mine].all()
                          else "solution puts the runway behind the camera")
            continue
        i = ok[np.argmin(rms[ok])]
        reasons[b] = ""
        rvec[b] = cv2.Rodrigues(R[i])[0].ravel() if refined else rv[i]
        tvec[b], err[b] = tv[i], rms[i]
        position[b] = -R[i].T @ tv[i]


def _sqpnp_start(z: np.ndarray, x: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray] | str:
    """OpenCV's SQPNP pose (R (3, 3), t (3,)) of one row, or the failure reason."""
    try:
        ok, rv, tv = cv2.solvePnP(z, np.ascontiguousarray(x), K, None, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error as e:
        msg = str(e).strip().splitlines()[-1] if str(e).strip() else "cv2.error"
        logger.debug("PnP ippe_lm: OpenCV error %s in the SQPNP fallback", msg)
        return f"OpenCV error: {msg}"
    if not ok:
        return "non-finite solution"  # the IPPE poses were not finite and SQPNP found none
    return rotvec_to_matrix(np.asarray(rv, np.float64).reshape(1, 3))[0], np.asarray(tv, np.float64).reshape(3)


def _solve_ippe_lm(
    z: np.ndarray, x: np.ndarray, K: np.ndarray, todo: np.ndarray, reasons: list[str],
    rvec: np.ndarray, tvec: np.ndarray, err: np.ndarray, position: np.ndarray,
) -> None:
    """``"ippe_lm"`` for the usable rows ``todo``, vectorised; writes the outputs and reasons of those rows.

    Both IPPE poses of every row, LM on all of them at once, then per row the valid candidate (finite, all
    corners in front of the camera) with the lower final error, as :func:`_pick_best` does row by row.
    """
    xs = x[todo]
    R, t = ippe_poses(z, xs, K)
    finite = np.all(np.isfinite(R), axis=(2, 3)) & np.all(np.isfinite(t), axis=2)  # (n, 2)
    R, t, cost = refine_candidates(z, xs, K, R, t)
    fallback = np.flatnonzero(~finite.any(axis=1))
    if fallback.size:  # no finite IPPE pose (e.g. the centroid projects to infinity): refine SQPNP's pose instead
        R, t, cost, finite = (np.concatenate([a, np.full_like(a[:, :1], f)], axis=1)
                              for a, f in ((R, np.nan), (t, np.nan), (cost, np.nan), (finite, False)))
        starts = {int(i): _sqpnp_start(z, xs[i], K) for i in fallback}
        rows = np.array([i for i, s in starts.items() if not isinstance(s, str)], dtype=int)
        for i, s in starts.items():
            if isinstance(s, str):
                reasons[todo[i]] = s
        if rows.size:
            R1 = np.stack([starts[int(i)][0] for i in rows])[:, None]
            t1 = np.stack([starts[int(i)][1] for i in rows])[:, None]
            R1, t1, c1 = refine_candidates(z, xs[rows], K, R1, t1)
            R[rows, 2], t[rows, 2], cost[rows, 2], finite[rows, 2] = R1[:, 0], t1[:, 0], c1[:, 0], True
    finite &= np.all(np.isfinite(t), axis=2) & np.all(np.isfinite(R), axis=(2, 3))
    depth = R[..., 2, 0, None] * z[:, 0] + R[..., 2, 1, None] * z[:, 1] + R[..., 2, 2, None] * z[:, 2] + t[..., 2, None]
    rms = np.sqrt(cost / 4.0)
    valid = finite & np.all(depth > 0, axis=2) & np.isfinite(rms)
    best = np.argmin(np.where(valid, rms, np.inf), axis=1)
    ok = valid.any(axis=1)
    for i in np.flatnonzero(~ok):
        if not reasons[todo[i]]:
            reasons[todo[i]] = ("non-finite solution" if not finite[i].all()
                                else "solution puts the runway behind the camera")
    i = np.flatnonzero(ok)
    if i.size == 0:
        return
    Rb, tb = R[i, best[i]], t[i, best[i]]
    rows = todo[i]
    rvec[rows], tvec[rows], err[rows] = matrix_to_rotvec(Rb), tb, rms[i, best[i]]
    position[rows] = -(Rb[:, 0] * tb[:, :1] + Rb[:, 1] * tb[:, 1:2] + Rb[:, 2] * tb[:, 2:])  # −Rᵀ t


def solve(points_2d: object, corners_3d: object, K: object, method: str = "ippe_lm") -> PnPResult:
    """Camera position from the four runway corners, batched.

    Args:
        points_2d: (4, 2) or (B, 4, 2) float pixels (OpenCV convention), corners in the order TR, TL, BL, BR.
            A list of B rows may be ragged: a row of the wrong shape fails on its own. Torch tensors are
            detached. An unbatched (4, 2) input gives B = 1.
        corners_3d: (4, 3) runway corners TR, TL, BL, BR in the runway frame, metres.
        K: (3, 3) pinhole intrinsics (no distortion).
        method: one of :data:`SOLVERS`, or ``"ippe_lm_rowwise"`` (see the module docstring).

    Returns:
        :class:`PnPResult` with (B, ...) arrays; failed rows are NaN with ``success`` False.

    Raises:
        ValueError: whole-call mistakes (shape of ``points_2d``, bad ``corners_3d`` or ``K``, unknown ``method``).
    """
    check_method(method)
    z = check_corners_3d(corners_3d)
    k = check_intrinsics(K)
    x, reasons = _rows(points_2d)
    B = x.shape[0]
    # the vectorised LM models K = [[A₂, c], [0, 0, 1]] exactly; check_intrinsics accepts a last row within 1e-8
    vectorised = method == "ippe_lm" and np.array_equal(k[2], [0.0, 0.0, 1.0])
    finite = np.all(np.isfinite(x), axis=(1, 2))
    in_range = np.all(np.abs(np.where(finite[:, None, None], x, 0.0)) <= MAX_COORD_PX, axis=(1, 2))
    degenerate = np.zeros(B, dtype=bool)
    usable = finite & in_range
    if usable.any():
        degenerate[usable] = _degenerate_rows(x[usable])
    rvec, tvec, err, position = (np.full((B, 3), np.nan), np.full((B, 3), np.nan), np.full(B, np.nan),
                                 np.full((B, 3), np.nan))
    owner: list[int] = []
    cand_r: list[np.ndarray] = []
    cand_t: list[np.ndarray] = []
    todo: list[int] = []
    for b in range(B):
        if reasons[b]:
            continue
        if not finite[b]:
            reasons[b] = "non-finite keypoints"
        elif not in_range[b]:
            reasons[b] = f"keypoints farther than {MAX_COORD_PX:.0e} px from the image origin"
        elif degenerate[b]:
            reasons[b] = "collinear or coincident keypoints"
        elif vectorised:
            todo.append(b)
        else:
            try:
                cands = _opencv_candidates(method, z, np.ascontiguousarray(x[b]), k)
            except cv2.error as e:
                msg = str(e).strip().splitlines()[-1] if str(e).strip() else "cv2.error"
                logger.debug("PnP %s: OpenCV error %s", method, msg)
                reasons[b] = f"OpenCV error: {msg}"
                continue
            reasons[b] = "no solution"  # until a valid candidate is found below
            for r, t in cands:
                owner.append(b)
                cand_r.append(r)
                cand_t.append(t)
    if todo:
        _solve_ippe_lm(z, x, k, np.asarray(todo), reasons, rvec, tvec, err, position)
    if owner:
        _pick_best(method, z, x, k, np.asarray(owner), np.stack(cand_r), np.stack(cand_t),
                   reasons, rvec, tvec, err, position)
    success = np.array([r == "" for r in reasons], dtype=bool)
    return PnPResult(
        position=position, success=success, reproj_error_px=err, rvec=rvec, tvec=tvec,
        method=method, reason=tuple(reasons),
    )
