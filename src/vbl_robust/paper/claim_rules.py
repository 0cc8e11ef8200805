"""The verdict rules of :mod:`.claims`: the verdicts, the thresholds, the records of a claim (:class:`ClaimRule`: what
is checked and how, :class:`ClaimResult`: what its computation gives, :class:`Claim`: the table's row), and the pure
functions that judge a claim's parts from numbers (None: not measurable). The rules themselves are stated in
:mod:`.claims`'s docstring.

Every part is judged with its noise: survival comparisons by the exact McNemar test (:func:`survival_parts`), a
rate by its exact interval (:func:`rate_part`, :func:`rough_part`), evaluations by the signed-rank test
(:func:`fewer_evals`), and every statistic of per-image values (a median, a ratio or a difference of medians, the
minimum of a mean curve) by a paired percentile bootstrap over the images (:func:`resamples`,
:func:`percentile_ci`: :data:`BOOT_N` resamples of the image indices, one resample shared by every method and
budget, from a generator seeded with :data:`BOOT_SEED` — the same stores give the same intervals). A statistic is
then held against its threshold by :func:`in_range`: *holds* when its 95 % interval lies on the claimed side,
*contradicted* when it lies on the other, *tie* when it straddles the threshold."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..analysis.breach import survived
from ..analysis.reference import REFERENCE_METHOD
from ..report.html import fmt_num
from ..search.api import METHODS as SEARCH_METHODS
from ..stats import ALPHA, LEVEL, ClaimVerdict, Rate, claim_verdict, holm, paired
from ..store.rows import JobRow

#: The verdicts of a claim, in the order the claims page counts them (:class:`~vbl_robust.stats.ClaimVerdict`).
VERDICTS = tuple(ClaimVerdict)
HOLDS, PARTLY, TIE, CONTRADICTED, FAILS, NOT_RUN = VERDICTS
#: A part's outcome: a rule's True / False, a test's verdict, or None (not measurable).
Outcome = bool | ClaimVerdict | None
ABOUT_AS_ACCURATE = 1.25
TIME_FACTOR = 2.0
NEAR_ZERO_PCT = 5.0
PLATEAU_M, PLATEAU_FACTOR, PLATEAU_CHANGE, CROSS_BY_S = 500.0, 2.0, 0.2, 2.0
NEAR_M, PHI_TOL_DEG, PHI_PCT = 2600.0, 5.0, 10.0
RA_PCT, RA_BY_ITER, PO_SPREAD = 20.0, 10, 0.25
ROUGH_SHARE_PCT = 50.0
#: The bootstrap behind every interval on a statistic of per-image values: resamples, and the generator's seed.
BOOT_N, BOOT_SEED = 2000, 20250

#: How every interval and test of the claims is made (the line under the claims table).
METHODS = ("Every verdict is a test or a 95 % interval: survival compared per box by the exact McNemar test "
           "(Holm-adjusted over the claim's tests); a rate by its exact (Clopper-Pearson) interval; evaluations to "
           "a breach by the Wilcoxon signed-rank test; a median, a ratio or difference of medians, a mean curve by "
           f"a paired percentile bootstrap over the images ({BOOT_N} resamples, seed {BOOT_SEED}); φ_crit by the "
           "exact interval of survival at each budget. A claim *holds* when its interval lies on the claimed side "
           "of the threshold (or its test is significant that way), is *contradicted* when it lies on the other, "
           "and is a *tie* when it straddles the threshold.")


@dataclass(frozen=True)
class Claim:
    """One row of the claims table: the paper's statement, our and the dense grid's numbers, the verdict (one of
    :data:`VERDICTS`), why, and the number of images it is computed on."""

    experiment: str
    claim: str
    ours: str
    truth: str
    verdict: ClaimVerdict
    reason: str
    images: int


@dataclass(frozen=True)
class ClaimResult:
    """What a claim's computation gives on its experiments' complete images: our numbers (``ours``), the dense
    grid's (``truth``, ``""`` without one), the verdict (one of :data:`VERDICTS`), why, and the number of images."""

    ours: str
    truth: str
    verdict: ClaimVerdict
    reason: str
    images: int


@dataclass(frozen=True)
class ClaimRule:
    """One claim of the paper as checked: the experiments it is computed on, its statement, and its computation
    (one :class:`ClaimResult` from an opened experiment per name of ``experiments``, None where one is missing)."""

    experiments: tuple[str, ...]
    claim: str
    compute: Callable[..., ClaimResult]


def known_method(method: str) -> str:
    """``method`` when it names a search method or the dense-grid reference; ``ValueError`` otherwise: a misspelt
    name in a claim's computation must fail, not read as a method without rows."""
    if method not in SEARCH_METHODS and method != REFERENCE_METHOD:
        raise ValueError(f"claims: unknown method {method!r}; methods are {', '.join(SEARCH_METHODS)} and "
                         f"{REFERENCE_METHOD!r}")
    return method


# -- verdict rules: pure functions of numbers (None = not measurable) ------------------------------------------
def combine(parts: Sequence[Outcome]) -> ClaimVerdict:
    """The verdict of a claim from its parts' outcomes (see the module docstring)."""
    known = [p for p in parts if p is not None]
    if not known:
        return NOT_RUN
    if any(p == ClaimVerdict.CONTRADICTED for p in known):
        return CONTRADICTED
    held = [p is True or p == ClaimVerdict.HOLDS for p in known]
    if len(known) == len(parts) and all(held):
        return HOLDS
    if any(held):
        return PARTLY
    return TIE if any(p == ClaimVerdict.TIE for p in known) else FAILS


def survival_parts(rows: Sequence[JobRow], eps_safe_m: float, pairs: Sequence[tuple[str, str]],
                   labels: Sequence[str]) -> list[tuple[list[Outcome], str]]:
    """The claim "``low`` survives less than ``high`` at every box of ``labels``" for each ``(low, high)`` of
    ``pairs``, judged with its noise: per box the exact McNemar test of their survival on the images both have a
    row for, Holm-adjusted over every test of ``pairs`` × ``labels``, and its :class:`ClaimVerdict`. One group per
    pair: (the boxes' outcomes, ``"georobust < random: ±2° tie (3 vs 1 of 100, p = 1); …"``)."""
    ok = {(r.method, r.box_label, r.sample_id): survived(r, eps_safe_m) for r in rows}
    tests = []
    for low, high in pairs:
        known_method(low), known_method(high)
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


# -- intervals: a paired bootstrap over the images, held against a threshold ----------------------------------
def resamples(n: int, n_boot: int = BOOT_N, seed: int = BOOT_SEED) -> np.ndarray:
    """(n_boot, n) image indices drawn with replacement from a generator seeded with ``(seed, n)``: the same
    images give the same resamples, and one resample serves every method and budget of a claim (paired)."""
    return np.random.default_rng([seed, n]).integers(0, n, size=(n_boot, n))


def percentile_ci(values: np.ndarray, level: float = LEVEL) -> tuple[float, float]:
    """The percentile interval of bootstrap ``values`` at ``level`` (order statistics: an ∞ stays ∞); NaN values
    (a statistic undefined on a resample) are dropped, (NaN, NaN) when half or more are."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    ok = v[~np.isnan(v)]
    if ok.size == 0 or ok.size * 2 <= v.size:
        return math.nan, math.nan
    a = (1.0 - level) / 2.0
    lo, hi = np.quantile(ok, [a, 1.0 - a], method="inverted_cdf")
    return float(lo), float(hi)


def _quiet(fn, x: np.ndarray, axis: int = -1) -> np.ndarray:
    """``fn`` (np.nanmedian, np.nanmean, …) along ``axis`` without the all-NaN warning (NaN there)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(x, axis=axis)


def in_range(lo: float, hi: float, low: float = -math.inf, high: float = math.inf) -> ClaimVerdict | None:
    """The claim "the statistic lies in [low, high]" judged by its interval [lo, hi]: *holds* when the interval
    lies inside, *contradicted* when it lies wholly outside, a *tie* when it straddles a bound; None for an unknown
    interval."""
    if math.isnan(lo) or math.isnan(hi):
        return None
    if low <= lo and hi <= high:
        return ClaimVerdict.HOLDS
    if hi < low or lo > high:
        return ClaimVerdict.CONTRADICTED
    return ClaimVerdict.TIE


def _num(v: float, at: Sequence[float] = ()) -> str:
    """:func:`fmt_num` of ``v``, with more digits where it would read as one of the thresholds ``at`` it is not (an
    interval's end at 0.2505 must not print as the 0.25 it exceeds)."""
    text = fmt_num(v)
    for t in at:
        if math.isfinite(v) and v != t and text == fmt_num(float(t)):
            return f"{v:.6g}" if f"{v:.4g}" == f"{t:.4g}" else f"{v:.4g}"
    return text


def _ci(est: float, lo: float, hi: float, unit: str = "", at: Sequence[float] = ()) -> str:
    """``"3.09 [2.05, 4.71]"`` (``unit`` after each number, e.g. " m"; ``at``: the thresholds it is held
    against, :func:`_num`)."""
    return f"{_num(est, at)}{unit} [{_num(lo, at)}{unit}, {_num(hi, at)}{unit}]"


def _said(v: Outcome, threshold: str) -> str:
    """A part's verdict in words; a tie says which ``threshold`` its interval straddles (given one)."""
    if v is None:
        return "not measured"
    if v == ClaimVerdict.TIE:
        return f"tie (the interval straddles {threshold})" if threshold else "tie"
    return v.value if isinstance(v, ClaimVerdict) else {True: "yes", False: "no"}[v]


def _all(parts: Sequence[ClaimVerdict | None]) -> ClaimVerdict | None:
    """One verdict of parts that must all hold: contradicted if one is, holds if all do, else a tie."""
    if any(p is None for p in parts):
        return None
    if ClaimVerdict.CONTRADICTED in parts:
        return ClaimVerdict.CONTRADICTED
    return ClaimVerdict.HOLDS if all(p == ClaimVerdict.HOLDS for p in parts) else ClaimVerdict.TIE


def _finite_median(x: np.ndarray) -> np.ndarray:
    """Median along the last axis over the finite values; ∞ where there is none (nothing breached)."""
    x = np.where(np.isfinite(x), x, np.nan)
    m = _quiet(np.nanmedian, x)
    return np.where(np.isnan(m), math.inf, m)


def median_ratio(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float]:
    """(median(a) / median(b), its bootstrap interval) over paired per-image values (NaN: no value there, left
    out of its median)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    est = float(np.nanmedian(a) / np.nanmedian(b))
    idx = resamples(a.size)
    with np.errstate(divide="ignore", invalid="ignore"):
        boot = _quiet(np.nanmedian, a[idx]) / _quiet(np.nanmedian, b[idx])
    return (est, *percentile_ci(boot))


def pnp_part(a: Sequence[float], b: Sequence[float], what: str,
             factor: float = ABOUT_AS_ACCURATE) -> tuple[Outcome, str]:
    """Rule 1 on one keypoint source: ippe_lm's median relative error (``a``, per image; NaN: a failed solve) at
    most ``factor`` × iterative's (``b``), judged by the bootstrap interval of the ratio of the medians."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if not (np.isfinite(a).any() and np.isfinite(b).any()):
        return None, f"{what}: no successful solve to compare — not measured"
    est, lo, hi = median_ratio(a, b)
    v = in_range(lo, hi, high=factor)
    return v, (f"{what}: median ratio ippe_lm / iterative {_ci(est, lo, hi, at=(factor,))} over {a.size} images "
               f"≤ {factor:g}: {_said(v, f'{factor:g}')}")


def times_part(times: Mapping[str, Sequence[float]], factor: float = TIME_FACTOR) -> tuple[Outcome, str]:
    """Rule 3: per method the seconds to its first breach on the same images (∞: none; NaN: unknown), the median
    over the images it breaches; the slowest and the fastest method (on the data) differ by ≥ ``factor``×, judged
    by the bootstrap interval of the ratio of their medians (a tie when no method breaches: nothing to compare)."""
    if len(times) < 2:
        return None, "fewer than two methods timed — not measured"
    t = {m: np.asarray(v, dtype=np.float64) for m, v in times.items()}
    med = {m: float(_finite_median(v)) for m, v in t.items()}
    fast, slow = min(med, key=med.__getitem__), max(med, key=med.__getitem__)
    if not math.isfinite(med[fast]):
        n = max(len(v) for v in t.values())
        return ClaimVerdict.TIE, f"no method breaches on any of {n} images: no time to a breach to compare — tie"
    if med[fast] <= 0:
        return None, "a median time to a breach of 0 s — not measured"
    idx = resamples(t[fast].size)
    with np.errstate(divide="ignore", invalid="ignore"):
        boot = _finite_median(t[slow][idx]) / _finite_median(t[fast][idx])
    lo, hi = percentile_ci(boot)
    v = in_range(lo, hi, low=factor)
    ratio = _ci(med[slow] / med[fast], lo, hi, at=(factor,))
    return v, (f"median time to a breach, slowest / fastest ({slow} / {fast}) {ratio} ≥ {factor:g}: "
               f"{_said(v, f'{factor:g}')}")


def plateau_part(w1: Sequence[float], w2: Sequence[float], budgets: tuple[str, str], who: str = "apgd",
                 level: float = PLATEAU_M) -> tuple[Outcome, str]:
    """Rule 5, first part: ``who``'s median worst errors at its last two time budgets (per image ``w1``, ``w2``;
    NaN: no value) each within ×:data:`PLATEAU_FACTOR` of ``level`` and changing by ≤ :data:`PLATEAU_CHANGE` of
    the larger — each judged by its bootstrap interval (the change signed: (m2 − m1) / max(m1, m2))."""
    a, b = np.asarray(w1, dtype=np.float64), np.asarray(w2, dtype=np.float64)
    if a.size == 0 or not (np.isfinite(a).any() and np.isfinite(b).any()):
        return None, f"{who}'s medians at its last two budgets — not measured"
    idx = resamples(a.size)
    m1, m2 = float(np.nanmedian(a)), float(np.nanmedian(b))
    b1, b2 = _quiet(np.nanmedian, a[idx]), _quiet(np.nanmedian, b[idx])
    with np.errstate(divide="ignore", invalid="ignore"):
        change = (b2 - b1) / np.maximum(b1, b2)
    cis = [percentile_ci(b1), percentile_ci(b2), percentile_ci(change)]
    near = (level / PLATEAU_FACTOR, level * PLATEAU_FACTOR)
    parts = [in_range(*cis[0], *near), in_range(*cis[1], *near), in_range(*cis[2], -PLATEAU_CHANGE, PLATEAU_CHANGE)]
    v = _all(parts)
    pct = 100 * PLATEAU_CHANGE
    bounds = f"{near[0]:g} or {near[1]:g} m"
    change = _ci(100 * (m2 - m1) / max(m1, m2), 100 * cis[2][0], 100 * cis[2][1], " %", (-pct, pct))
    return v, (f"{who}'s median worst error {budgets[0]} {_ci(m1, *cis[0], ' m', near)}, {budgets[1]} "
               f"{_ci(m2, *cis[1], ' m', near)} within ×{PLATEAU_FACTOR:g} of {level:g} m "
               f"({_said(parts[0], bounds)}, {_said(parts[1], bounds)}); change {change} within ±{pct:g} % "
               f"({_said(parts[2], f'±{pct:g} %')}): {_said(v, '')}")


def cross_part(worst: Sequence[Sequence[float]], budgets: Sequence[str], threshold: float,
               who: str = "georobust") -> tuple[Outcome, str]:
    """Rule 5, second part: ``who``'s median worst error exceeds ``threshold`` at some budget ≤ :data:`CROSS_BY_S`
    (``worst[j]``: per image at ``budgets[j]``, the same images; NaN: no value) — the largest of those medians,
    judged by its bootstrap interval (one statistic for "some budget": no test per budget to adjust)."""
    w = [np.asarray(v, dtype=np.float64) for v in worst]
    if not w or not any(np.isfinite(v).any() for v in w):
        return None, f"{who}'s medians at budgets ≤ {CROSS_BY_S:g} s — not measured"
    meds = [float(_quiet(np.nanmedian, v)) for v in w]
    est = max(m for m in meds if not math.isnan(m))
    at = budgets[meds.index(est)]
    idx = resamples(w[0].size)
    boot = _quiet(np.nanmax, np.stack([_quiet(np.nanmedian, v[idx]) for v in w]), axis=0)
    lo, hi = percentile_ci(boot)
    v = in_range(lo, hi, low=math.nextafter(threshold, math.inf))
    return v, (f"{who}'s largest median worst error at budgets ≤ {CROSS_BY_S:g} s ({at}) "
               f"{_ci(est, lo, hi, ' m', (threshold,))} > {threshold:g} m: {_said(v, f'{threshold:g} m')}")


def phi_interval(levels: Sequence[float], budgets: Sequence[float],
                 pct: float = PHI_PCT) -> tuple[float, float, float]:
    """(φ_crit, low, high) of images whose smallest breaching budgets are ``levels`` (∞: none within ``budgets``):
    φ_crit is the smallest budget at which survival drops below ``pct`` % (:func:`~vbl_robust.analysis.levels.
    phi_crit`); low the smallest at which the exact 95 % interval of survival reaches below ``pct`` (it may have
    dropped there), high the smallest at which the whole interval is below (it surely has); ∞ for "not within
    the budgets". Pointwise intervals, so [low, high] is as wide as each budget's noise."""
    lv = np.asarray(levels, dtype=np.float64)
    phi = lo = hi = math.inf
    for b in sorted(budgets):
        r = Rate(int(np.sum(lv > b)), int(lv.size))
        ci = r.ci
        phi = b if math.isinf(phi) and r.pct < pct else phi
        lo = b if math.isinf(lo) and ci.low < pct else lo
        hi = b if math.isinf(hi) and ci.high < pct else hi
    return float(phi), float(lo), float(hi)


def phi_text(phi: float, lo: float, hi: float, limit: float) -> str:
    """``"45° [35°, ≥ 45°]"`` (∞: ``≥ limit``, not reached within the budgets)."""
    def one(v: float) -> str:
        return f"≥ {limit:g}°" if not math.isfinite(v) else f"{v:g}°"

    return f"{one(phi)} [{one(lo)}, {one(hi)}]"


def ra_part(ra: np.ndarray, by: int = RA_BY_ITER, pct: float = RA_PCT) -> tuple[Outcome, str]:
    """Rule 7, first part: the lowest mean RA(k) (%) over k ≤ ``by`` is < ``pct``, judged by its bootstrap
    interval (the minimum recomputed on each resample). ``ra``: (runs, iterations), RA(k) of run i at column
    k − 1, NaN after its last iteration. None when fewer than ``by`` iterations ran and it has not held."""
    ra = np.asarray(ra, dtype=np.float64)
    if ra.size == 0:
        return None, "no RA(k) — not measured"
    early = ra[:, :by]
    mean = _quiet(np.nanmean, early, axis=0)
    if np.isnan(mean).all():
        return None, "no RA(k) — not measured"
    k = int(np.nanargmin(mean))
    boot = _quiet(np.nanmin, _quiet(np.nanmean, early[resamples(ra.shape[0])], axis=1))
    lo, hi = percentile_ci(boot)
    v = in_range(lo, hi, high=math.nextafter(pct, -math.inf))
    if v != ClaimVerdict.HOLDS and ra.shape[1] < by:
        v = None
    return v, (f"lowest mean RA(k ≤ {by}) {_ci(float(mean[k]), lo, hi, ' %', (pct,))} at k = {k + 1} < {pct:g} % "
               f"({ra.shape[1]} iterations ran): {_said(v, f'{pct:g} %')}")


def po_part(po: np.ndarray, spread: float = PO_SPREAD) -> tuple[Outcome, str]:
    """Rule 7, second part: mean |PO_k| rises above its first value and, over the second half of the iterations,
    varies by ≤ ``spread`` × that rise — judged by the bootstrap intervals of the rise (> 0) and of the ratio
    (tail's max − min) / rise (≤ ``spread``). ``po``: (runs, iterations), NaN after a run's last iteration;
    None for fewer than 4 iterations."""
    po = np.asarray(po, dtype=np.float64)
    if po.ndim != 2 or po.shape[1] < 4:
        return None, "fewer than 4 iterations of |PO_k| — not measured"

    def stats(mean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rise = np.nanmax(mean, axis=-1) - mean[..., 0]
        tail = mean[..., mean.shape[-1] // 2:]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(rise > 0, (np.nanmax(tail, axis=-1) - np.nanmin(tail, axis=-1)) / rise, math.inf)
        return rise, ratio

    mean = _quiet(np.nanmean, po, axis=0)
    rise, ratio = (float(x) for x in stats(mean))
    b_rise, b_ratio = stats(_quiet(np.nanmean, po[resamples(po.shape[0])], axis=1))
    ci_rise, ci_ratio = percentile_ci(b_rise), percentile_ci(b_ratio)
    parts = [in_range(*ci_rise, low=math.nextafter(0.0, 1.0)), in_range(*ci_ratio, high=spread)]
    v = _all(parts)
    tail = mean[len(mean) // 2:]
    return v, (f"mean |PO_k| {fmt_num(float(mean[0]))} → max {fmt_num(float(np.nanmax(mean)))}: rise "
               f"{_ci(rise, *ci_rise, at=(0.0,))} > 0 ({_said(parts[0], '0')}); over k = "
               f"{len(mean) - len(tail) + 1}…{len(mean)} {fmt_num(float(np.nanmin(tail)))}–"
               f"{fmt_num(float(np.nanmax(tail)))}, spread / rise {_ci(ratio, *ci_ratio, at=(spread,))} ≤ {spread:g} "
               f"({_said(parts[1], f'{spread:g}')}): {_said(v, '')}")


def rough_part(jumps: Sequence[float], eps_safe_m: float, share_pct: float = ROUGH_SHARE_PCT) -> tuple[str, str]:
    """Claim 9: (verdict, why) from each complete grid's largest jump between neighbours: the share of images
    jumping by > ``eps_safe_m`` with its exact 95 % interval — "holds" when the interval lies at or above
    ``share_pct`` %, "tie" when it straddles it, "partly" when it lies below but some image jumps (a jump
    observed on a grid is a fact, its share the estimate), "does not hold" when none does."""
    if not len(jumps):
        return NOT_RUN, "no complete dense grid in the store (run with --grid-step > 0)"
    r = Rate(int(np.sum(np.asarray(jumps) > eps_safe_m)), len(jumps))
    ci = r.ci
    verdict = (HOLDS if ci.low >= share_pct else TIE if ci.high >= share_pct else PARTLY if r.k else FAILS)
    said = {HOLDS: f"at least {share_pct:g} %: holds", TIE: f"the interval straddles {share_pct:g} %: tie",
            PARTLY: f"below {share_pct:g} % but above 0: partly", FAILS: "no image jumps: does not hold"}[verdict]
    return verdict, (f"{r.k} of {r.n} complete grids ({r.text(1)}, exact 95 %) jump by > {eps_safe_m:g} m between "
                     f"neighbours; holds from {share_pct:g} % of the images, partly when some do — {said}")


def judge(parts: Sequence[tuple[Outcome, str]], groups: Sequence[tuple[list[Outcome], str]] = ()) -> tuple[str, str]:
    """(verdict, reason) of a claim's parts ``(outcome, what was compared)`` and tested groups (:func:`survival_parts`:
    several outcomes, one text each)."""
    mark = {True: "yes", False: "no", None: "not measured"}
    outcomes = [ok for ok, _ in parts] + [o for out, _ in groups for o in out]
    held = sum(o is True or o == ClaimVerdict.HOLDS for o in outcomes)
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
