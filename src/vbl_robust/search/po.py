"""Selection of potentially optimal (PO) rectangles — Gablonsky's lemma, in the *minimisation* sense.

A rectangle ``p`` of size ``sigma_p`` and value ``f_p`` is potentially optimal if some rate ``K >= 0`` makes
``f_p - K sigma_p`` the lowest of all rectangles and at least ``eps * scale`` below the best value. With the
best value ``m_c`` of each size class ``c`` (only class minima matter) this is equivalent to:

(a) ``f_p`` is the best of its class (GeoRobust's α-expansion relaxes this to "``f_p`` <= the α-th smallest value
    of the class");
(b) ``lo(p) <= up(p)`` with ``lo = max(0, max over smaller classes (f_p - m_c) / (sigma_p - sigma_c))`` and
    ``up = min over larger classes (m_c - f_p) / (sigma_c - sigma_p)`` (+inf when there is none);
(c) when a larger class exists: ``f_p - up * sigma_p <= f_min - eps * max(|f_min|, f_scale)``.

The ``f_scale`` floor keeps (c) meaningful when ``f_min`` is close to 0, where the classic relative test
(``f_scale = 0``) degenerates to ``eps = 0``.

Size classes are keyed on an integer (larger key = smaller size) so equal sizes compare equal exactly.
"""

from __future__ import annotations

import numpy as np


def potentially_optimal(
    keys: np.ndarray,
    sizes: np.ndarray,
    f: np.ndarray,
    *,
    alpha: int = 1,
    ties: str = "all",
    eps: float = 1e-4,
    f_scale: float = 0.0,
) -> np.ndarray:
    """Indices of the PO rectangles, sorted ascending.

    Args:
        keys: ``(m,)`` integer size-class key per rectangle (a larger key is a strictly smaller size).
        sizes: ``(m,)`` size per rectangle (equal for equal keys).
        f: ``(m,)`` finite values to *minimise*.
        alpha: candidates of a class are the rectangles with ``f <=`` its α-th smallest value (1 = classic).
        ties: ``"all"`` keeps every candidate (Jones: all ties divided); ``"one"`` keeps the first rectangle
            (lowest index) of each distinct value (Gablonsky's DIRECT-L); ``"alpha"`` keeps at most α per class.
        eps, f_scale: the ε test (c).
    """
    keys = np.asarray(keys)
    f = np.asarray(f, dtype=np.float64)
    m = len(f)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    idx = np.arange(m)
    order = np.lexsort((idx, f, keys))  # by key (large size first), then value, then index: stable
    sk, sf = keys[order], f[order]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    ends = np.r_[starts[1:], m]
    class_min = sf[starts]
    class_size = np.asarray(sizes, dtype=np.float64)[order][starts]

    cand, cand_class = [], []
    for c, (a, b) in enumerate(zip(starts, ends, strict=True)):
        limit = sf[min(a + alpha, b) - 1]
        members = order[a:b][sf[a:b] <= limit]
        if ties == "one":
            vals = f[members]
            keep = np.r_[True, vals[1:] != vals[:-1]]  # members are sorted by (value, index)
            members = members[keep]
        elif ties == "alpha":
            members = members[:alpha]  # sorted by (value, index): the α best, older first among equals
        cand.extend(members.tolist())
        cand_class.extend([c] * len(members))
    cand = np.asarray(cand, dtype=np.int64)
    cc = np.asarray(cand_class, dtype=np.int64)

    fp = f[cand][:, None]
    sp = class_size[cc][:, None]
    ci = np.arange(len(starts))[None, :]
    larger = ci < cc[:, None]
    smaller = ci > cc[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = (class_min[None, :] - fp) / (class_size[None, :] - sp)
    up = np.where(larger, slope, np.inf).min(axis=1)
    lo = np.maximum(np.where(smaller, slope, -np.inf).max(axis=1), 0.0)
    f_min = float(f.min())
    threshold = f_min - eps * max(abs(f_min), f_scale)
    has_larger = larger.any(axis=1)
    with np.errstate(invalid="ignore"):
        eps_ok = ~has_larger | (f[cand] - up * sp[:, 0] <= threshold)
    ok = (lo <= up) & eps_ok
    return np.sort(cand[ok])
