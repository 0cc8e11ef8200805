"""The verdict rules of :mod:`.claims`: the verdicts, the thresholds, the :class:`Claim` row, and the pure
functions that judge a claim's parts from numbers (None: not measurable). The rules themselves are stated in
:mod:`.claims`'s docstring."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..campaigns import metrics as mx
from ..campaigns.store import JobRow
from ..stats import ALPHA, ClaimVerdict, Rate, claim_verdict, holm, paired
from .html import fmt_num

VERDICTS = ("holds", "partly", "tie", "contradicted", "does not hold", "not run yet")
HOLDS, PARTLY, TIE, CONTRADICTED, FAILS, NOT_RUN = VERDICTS
#: A part's outcome: a rule's True / False, a test's verdict, or None (not measurable).
Outcome = bool | ClaimVerdict | None
ABOUT_AS_ACCURATE = 1.25
TIME_FACTOR = 2.0
NEAR_ZERO_PCT = 5.0
PLATEAU_M, PLATEAU_FACTOR, PLATEAU_CHANGE, CROSS_BY_S = 500.0, 2.0, 0.2, 2.0
NEAR_M, PHI_TOL_DEG = 2600.0, 5.0
RA_PCT, RA_BY_ITER, PO_SPREAD = 20.0, 10, 0.25


@dataclass(frozen=True)
class Claim:
    """One row of the claims table: the paper's statement, our and the dense grid's numbers, the verdict (one of
    :data:`VERDICTS`), why, and the number of images it is computed on."""

    experiment: str
    claim: str
    ours: str
    truth: str
    verdict: str
    reason: str
    images: int


# -- verdict rules: pure functions of numbers (None = not measurable) ------------------------------------------
def combine(parts: Sequence[Outcome]) -> str:
    """The verdict of a claim from its parts' outcomes (see the module docstring)."""
    known = [p for p in parts if p is not None]
    if not known:
        return NOT_RUN
    if any(p is ClaimVerdict.CONTRADICTED for p in known):
        return CONTRADICTED
    held = [p is True or p is ClaimVerdict.HOLDS for p in known]
    if len(known) == len(parts) and all(held):
        return HOLDS
    if any(held):
        return PARTLY
    return TIE if any(p is ClaimVerdict.TIE for p in known) else FAILS


def survival_parts(rows: Sequence[JobRow], eps_safe_m: float, pairs: Sequence[tuple[str, str]],
                   labels: Sequence[str]) -> list[tuple[list[Outcome], str]]:
    """The claim "``low`` survives less than ``high`` at every box of ``labels``" for each ``(low, high)`` of
    ``pairs``, judged with its noise: per box the exact McNemar test of their survival on the images both have a
    row for, Holm-adjusted over every test of ``pairs`` × ``labels``, and its :class:`ClaimVerdict`. One group per
    pair: (the boxes' outcomes, ``"georobust < random: ±2° tie (3 vs 1 of 100, p = 1); …"``)."""
    ok = {(r.method, r.box_label, r.sample_id): mx.survived(r, eps_safe_m) for r in rows}
    tests = []
    for low, high in pairs:
        for lab in labels:
            ids = [sid for (m, b, sid) in ok if m == low and b == lab and (high, lab, sid) in ok]
            tests.append((low, high, lab,
                          paired([ok[(low, lab, i)] for i in ids], [ok[(high, lab, i)] for i in ids]) if ids else None))
    adjusted = iter(holm([t.p_value for *_, t in tests if t is not None]))
    groups: dict[tuple[str, str], tuple[list[Outcome], list[str]]] = {}
    for low, high, lab, t in tests:
        outcomes, texts = groups.setdefault((low, high), ([], []))
        if t is None:
            outcomes.append(None)
            texts.append(f"{lab} not measured")
            continue
        t = dataclasses.replace(t, p_value=next(adjusted))
        v = claim_verdict(t, a_better=False)
        outcomes.append(v)
        texts.append(f"{lab} {v.value} ({t.only_a} vs {t.only_b} of {t.n}, p = {t.p_value:.2g})")
    return [(out, f"{low} survives less than {high}: " + ", ".join(texts))
            for (low, high), (out, texts) in groups.items()]


def rate_part(k: int, n: int, limit_pct: float) -> tuple[Outcome, str]:
    """The claim "the rate k/n is at most ``limit_pct`` %" judged with its exact 95 % interval: holds when the
    interval's top is ≤ the limit, contradicted when its bottom is above it, a tie when it straddles it."""
    if n == 0:
        return None, f"≤ {limit_pct:g} %: no images"
    r = Rate(k, n)
    ci = r.ci
    v = (ClaimVerdict.HOLDS if ci.high <= limit_pct else
         ClaimVerdict.CONTRADICTED if ci.low > limit_pct else ClaimVerdict.TIE)
    return v, f"{r.text(1)} of {n} ≤ {limit_pct:g} %: {v.value}"


def at_most(a: Sequence[float], b: Sequence[float]) -> bool | None:
    """True when ``a[i] ≤ b[i]`` at every i where both are known (NaN: unknown); None when none is. Claims 1 (``a``
    = ippe_lm's median, ``b`` = 1.25 × iterative's), 2, 4, 6 and 8 are made of such comparisons."""
    p = [(x, y) for x, y in zip(a, b, strict=True) if not (math.isnan(x) or math.isnan(y))]
    return all(x <= y for x, y in p) if p else None


def behind(a: Sequence[float], b: Sequence[float]) -> bool | None:
    """True when survival ``a`` ≥ ``b`` at every known budget and > at some (None when none is known)."""
    ok = at_most(b, a)
    return ok and not at_most(a, b)


def fewer_evals(a: Sequence[float], b: Sequence[float]) -> tuple[Outcome, str]:
    """The claim "method A needs fewer evaluations to a breach than B" on pairs ``(a[i], b[i])`` (the same image and
    box), judged by the Wilcoxon signed-rank test (``scipy.stats.wilcoxon``, two-sided, zero differences dropped):
    holds / tie / contradicted as :func:`vbl_robust.stats.claim_verdict` at α = 5 %."""
    from scipy.stats import rankdata, wilcoxon

    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    d = d[d != 0]
    if d.size == 0:
        return (None if len(a) == 0 else ClaimVerdict.TIE), f"evals to a breach: {len(a)} shared pairs, no difference"
    p = float(wilcoxon(d).pvalue)
    signed = float(np.sum(np.sign(d) * rankdata(np.abs(d))))  # the direction the test measures
    v = (ClaimVerdict.TIE if p >= ALPHA else ClaimVerdict.HOLDS if signed < 0 else ClaimVerdict.CONTRADICTED)
    mean = float(np.mean(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)))
    return v, (f"evals to a breach over {len(a)} shared (image, box) pairs: mean difference {fmt_num(mean)}, "
               f"Wilcoxon signed-rank p = {p:.2g}: {v.value}")


def times_differ(medians: Mapping[str, float], factor: float = TIME_FACTOR) -> bool | None:
    """True when the slowest and fastest methods' median times to a breach (∞: never) differ by ≥ ``factor``×;
    False when no method breaches; None for fewer than two methods."""
    if len(medians) < 2:
        return None
    finite = [v for v in medians.values() if math.isfinite(v)]
    if not finite:
        return False
    return len(finite) < len(medians) or (max(finite) > 0 and max(finite) >= factor * min(finite))


def plateaus_near(values: Sequence[float], level: float = PLATEAU_M) -> bool | None:
    """True when the last two known values (ascending budgets) lie in [level / f, level · f]
    (f = :data:`PLATEAU_FACTOR`) and differ by ≤ :data:`PLATEAU_CHANGE` × the larger (None for < 2 values)."""
    v = [x for x in values if math.isfinite(x)][-2:]
    if len(v) < 2:
        return None
    near = all(level / PLATEAU_FACTOR <= x <= level * PLATEAU_FACTOR for x in v)
    return near and abs(v[1] - v[0]) <= PLATEAU_CHANGE * max(v)


def crosses_by(budgets: Sequence[float], values: Sequence[float], threshold: float,
               by: float = CROSS_BY_S) -> bool | None:
    """True when some value at a budget ≤ ``by`` is > ``threshold`` (None when no such budget has a value)."""
    v = [x for b, x in zip(budgets, values, strict=True) if b <= by and math.isfinite(x)]
    return any(x > threshold for x in v) if v else None


def phi_near(phis: Sequence[float], target: float, tol: float = PHI_TOL_DEG) -> bool | None:
    """True when every φ_crit is within ``tol`` of ``target`` (∞ never is; None for no quartile)."""
    return all(abs(p - target) <= tol for p in phis) if phis else None


def ra_below(ra: Mapping[int, float], pct: float = RA_PCT, by: int = RA_BY_ITER) -> bool | None:
    """True when RA(k) (%, per iteration k) is < ``pct`` at some k ≤ ``by``; None when it is not and fewer than
    ``by`` iterations ran."""
    early = [v for k, v in ra.items() if k <= by and math.isfinite(v)]
    if early and min(early) < pct:
        return True
    return None if max(ra, default=0) < by else False


def rises_then_plateaus(po: Sequence[float]) -> bool | None:
    """True when |PO_k| (k = 1, 2, …) rises above its first value and, over the second half of the iterations,
    varies by ≤ :data:`PO_SPREAD` × that rise (max − first); None for fewer than 4 iterations."""
    if len(po) < 4:
        return None
    rise, tail = max(po) - po[0], po[len(po) // 2:]
    return rise > 0 and max(tail) - min(tail) <= PO_SPREAD * rise


def rough_verdict(jumps: Sequence[float], eps_safe_m: float) -> str:
    """Claim 9: "holds" when at least half the images' largest jumps are > ``eps_safe_m``, "partly" when some
    are, "does not hold" when none is, "not run yet" without images."""
    if not jumps:
        return NOT_RUN
    share = float(np.mean(np.asarray(jumps) > eps_safe_m))
    return HOLDS if share >= 0.5 else PARTLY if share > 0 else FAILS


def judge(parts: Sequence[tuple[Outcome, str]], groups: Sequence[tuple[list[Outcome], str]] = ()) -> tuple[str, str]:
    """(verdict, reason) of a claim's parts ``(outcome, what was compared)`` and tested groups (:func:`survival_parts`:
    several outcomes, one text each)."""
    mark = {True: "yes", False: "no", None: "not measured"}
    outcomes = [ok for ok, _ in parts] + [o for out, _ in groups for o in out]
    held = sum(o is True or o is ClaimVerdict.HOLDS for o in outcomes)
    texts = [t if isinstance(ok, ClaimVerdict) else f"{t} — {mark[ok]}" for ok, t in parts]
    texts += [f"{t} — {combine(out)}" for out, t in groups]
    return combine(outcomes), f"{held} of {len(outcomes)} parts hold: " + "; ".join(texts) + "."


def first_breach_s(row: JobRow, eps_safe_m: float, penalty_m: float) -> float:
    """Seconds on the search's clock to the row's first evaluation above ``eps_safe_m`` (non-finite values count
    as ``penalty_m``); ∞ when none; NaN without stamped times (``row`` needs its points)."""
    p = row.points
    if p is None or p.times is None:
        return math.nan
    hit = np.flatnonzero(np.where(np.isfinite(p.fs), p.fs, penalty_m) > eps_safe_m)
    return float(p.times[hit[0]]) if hit.size else math.inf


def largest_jump(xs: np.ndarray, fs: np.ndarray, penalty_m: float) -> tuple[float, float]:
    """(largest |ΔL| between neighbouring points of a 1-D grid (m), the slope it implies (m per unit of x))."""
    order = np.argsort(xs[:, 0])
    x, f = xs[order, 0], np.where(np.isfinite(fs), fs, penalty_m)[order]
    d, dx = np.abs(np.diff(f)), np.diff(x)
    i = int(np.argmax(d))
    return float(d[i]), float(d[i] / dx[i]) if dx[i] > 0 else math.inf
