"""The detector's validation protocol: its seeds, gates and goals, and the rule that decides whether a model ships.

- **Validation** (:data:`VALIDATION_SEEDS`, 510 approaches each): the sets every choice is made on — checkpoints,
  schedules, data mixes — compared on their pooled rows (the model card says when each seed was fixed and why).
- **Test** (:data:`TEST_SEEDS`, fixed before step J's training ended; each seed its own pool of 10 airports): the
  figures of the model card and BENCHMARKS.md, per seed and envelope. No choice is ever made on them.
- **Hardening** (:data:`HARDEN_SEED`): ``vbl-robust harden`` trains on approaches of their own airports; the seeds
  of the audits and of the protocol are refused (:data:`HARDEN_FORBIDDEN_SEEDS`), so a before/after audit and the
  protocol's figures never see a training image.
- **Gates** (:data:`GATES`: a model below them is not shipped) and **goals** (:data:`GOALS`), as fractions
  (position error in % of the slant distance).
- **Replacement rule** (:func:`replacement_verdict`): a candidate replaces the shipped model only when more of the
  pooled validation approaches survive *and* the exact paired (McNemar) test of the difference gives
  p < :data:`REPLACE_P`.

``benchmarks/detector_protocol.py`` measures a model on these seeds and writes the protocol JSON;
``vbl-robust ship CKPT --protocol P.json --against SHIPPED.json`` applies the rule and writes ``default.json`` from
it (:func:`info_from_protocol`).
"""

from __future__ import annotations

__all__ = ["GATES", "GOALS", "HARDEN_FORBIDDEN_SEEDS", "HARDEN_SEED", "REPLACE_P", "TEST_SEEDS", "VALIDATION_SEEDS", "info_from_protocol",
           "pooled_validation", "replacement_verdict"]

#: the validation seeds (the first is the former benchmark set on which v5–v7 were chosen: never quoted)
VALIDATION_SEEDS = (20_261_122, 20_261_202, 20_261_203, 20_261_204)
#: the test seeds (figures only)
TEST_SEEDS = (777_001, 31_337, 4_242)
#: the approaches ``vbl-robust harden`` trains on by default: their own airports (each seed has its own pool), never
#: an audit's (the audits' and the paper reproduction's seed 0), a validation or a test seed
HARDEN_SEED = 20_261_205
#: seeds hardening refuses to train on: the audit default (its images are the before/after audit's) and the
#: protocol's validation and test seeds (the figures a hardened model is judged by)
HARDEN_FORBIDDEN_SEEDS = (0, *VALIDATION_SEEDS, *TEST_SEEDS)
#: a model below these is not shipped (every test seed; the pooled validation seeds decide ``validated``)
GATES = {"detection_rate": 0.97, "survival_ippe_lm": 0.90}
#: what the detector aims at
GOALS = {"detection_rate": 0.98, "survival_ippe_lm": 0.95, "far_survival_ippe_lm": 0.90, "pos_err_pct_ippe_lm": 5.0}


def _all(rows: list[dict], env: str = "all") -> dict:
    return next(r for r in rows if r["envelope"] == env)


def pooled_validation(p: dict) -> dict:
    """Detection and survival over every validation seed of a protocol JSON, weighted by approaches."""
    rows = [_all(r) for r in p["validation"].values()]
    n = sum(r["n"] for r in rows)
    return {"seeds": list(p["validation"]), "n": n,
            **{k: sum(r[k] * r["n"] for r in rows) / n for k in ("detection_rate", "survival_ippe_lm")}}


#: the replacement rule's significance level (paired exact McNemar test on the pooled validation approaches)
REPLACE_P = 0.05


def replacement_verdict(new: dict, old: dict) -> tuple[bool, str]:
    """Whether protocol JSON ``new`` may replace the model of ``old`` (pooled validation: more approaches survive
    and the paired test gives p < ``REPLACE_P``), and the one-line reason."""
    from .evaluate import paired_seeds

    try:
        rows, c = paired_seeds(new, old, "validation")
    except ValueError as exc:
        return False, str(exc)
    seeds = [s for s, _ in rows]
    text = (f"pooled validation (seeds {', '.join(seeds)}, {c.n} approaches): {c.gain:+d} survive "
            f"({c.only_a} only with the candidate, {c.only_b} only with the shipped model), exact McNemar "
            f"p = {c.p_value:.4f}")
    return c.gain > 0 and c.p_value < REPLACE_P, text


def info_from_protocol(p: dict, version: int, epochs: int) -> dict:
    """``default.json``'s ``info`` from a protocol result: the note, ``validated`` (the gates on the pooled
    validation seeds) and the open goals (a test seed below a gate is listed among them)."""
    val = pooled_validation(p)
    tests = {s: rows for s, rows in p["test"].items()}
    surv = {s: _all(r)["survival_ippe_lm"] for s, r in tests.items()}
    det = {s: _all(r)["detection_rate"] for s, r in tests.items()}
    far = {s: _all(r, "far")["survival_ippe_lm"] for s, r in tests.items()}
    err = {s: _all(r)["pos_err_pct_ippe_lm"] for s, r in tests.items()}
    validated = val["detection_rate"] >= GATES["detection_rate"] and val["survival_ippe_lm"] >= GATES["survival_ippe_lm"]
    goals = []
    lo = min(surv, key=surv.get)
    if min(surv.values()) < GATES["survival_ippe_lm"] or min(det.values()) < GATES["detection_rate"]:
        goals.append(f"test seeds: nominal survival {100 * min(surv.values()):.1f} - {100 * max(surv.values()):.1f} %, "
                     f"below the 90 % gate on seed {lo} (far approaches {100 * far[lo]:.1f} %)")
    if min(surv.values()) < GOALS["survival_ippe_lm"]:
        goals.append(f"nominal survival goal 95 % open (test seeds {100 * min(surv.values()):.1f} - "
                     f"{100 * max(surv.values()):.1f} %; far {100 * min(far.values()):.1f} - {100 * max(far.values()):.1f} %)")
    if max(err.values()) > GOALS["pos_err_pct_ippe_lm"]:
        goals.append(f"median position error {min(err.values()):.2f} - {max(err.values()):.2f} % of slant distance on "
                     "the test seeds with ippe_lm (goal 5 %)")
    note = (f"validation (seeds {', '.join(val['seeds'])}, {val['n']} approaches): detection {100 * val['detection_rate']:.1f} %, nominal "
            f"survival {100 * val['survival_ippe_lm']:.1f} %; test seeds {', '.join(tests)}: survival "
            + ", ".join(f"{100 * v:.1f} %" for v in surv.values()) + "; see MODEL_CARD.md")
    return {"version": version, "trained_epochs": epochs, "note": note, "validated": bool(validated),
            "open_goals": goals}
