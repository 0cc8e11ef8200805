"""Ship a trained checkpoint as the default detector, with ``default.json`` written from its protocol results.

    python tools/ship_checkpoint.py CKPT.pt --version 10 --epochs 50 --protocol runs/protocol.json \
        --against runs/shipped_validation.json

``--protocol`` is the ``--json`` output of ``benchmarks/detector_protocol.py --split all`` for CKPT (stripped
checkpoints give the same outputs as the shipped file, since ``ship`` strips the same way). The note and the
open goals are computed from it; ``validated`` is the gate on the validation seeds pooled (detection ≥ 97 %,
nominal survival ≥ 90 %), and a miss of the gates on any test seed is listed among the open goals.

``--against`` is the shipped model's protocol JSON (``--split validation`` at least, with per-approach results):
the replacement rule of the model card (session 13) — the candidate survives more of the pooled validation
approaches *and* the exact paired (McNemar) test of the difference gives p < 0.05 — is checked before anything is
written. ``--force`` ships anyway and says so (e.g. a first model, or a rule deliberately set aside: write why in
the model card).
"""

from __future__ import annotations

import argparse
import json


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
    from vbl_robust.detect.evaluate import paired_seeds

    try:
        rows, c = paired_seeds(new, old, "validation")
    except ValueError as exc:
        return False, str(exc)
    seeds = [s for s, _ in rows]
    text = (f"pooled validation (seeds {', '.join(seeds)}, {c['n']} approaches): {c['gain']:+d} survive "
            f"({c['only_a']} only with the candidate, {c['only_b']} only with the shipped model), exact McNemar "
            f"p = {c['p_value']:.4f}")
    return c["gain"] > 0 and c["p_value"] < REPLACE_P, text


def info_from_protocol(p: dict, version: int, epochs: int) -> dict:
    val = pooled_validation(p)
    tests = {s: rows for s, rows in p["test"].items()}
    surv = {s: _all(r)["survival_ippe_lm"] for s, r in tests.items()}
    det = {s: _all(r)["detection_rate"] for s, r in tests.items()}
    far = {s: _all(r, "far")["survival_ippe_lm"] for s, r in tests.items()}
    err = {s: _all(r)["pos_err_pct_ippe_lm"] for s, r in tests.items()}
    from vbl_robust.detect.evaluate import GATES, GOALS

    validated = val["detection_rate"] >= GATES["detection_rate"] and val["survival_ippe_lm"] >= GATES["survival_ippe_lm"]
    goals = []
    lo = min(surv, key=surv.get)
    if min(surv.values()) < GATES["survival_ippe_lm"] or min(det.values()) < GATES["detection_rate"]:
        goals.append(f"test seeds: nominal survival {100 * min(surv.values()):.1f} - {100 * max(surv.values()):.1f} %, "
                     f"below the 90 % gate on seed {lo} (far approaches {100 * far[lo]:.1f} %)")
    if min(surv.values()) < GOALS["survival_ippe_lm"]:
        goals.append(f"nominal survival goal 95 % open (test seeds {100 * min(surv.values()):.1f} - "
                     f"{100 * max(surv.values()):.1f} %; far {100 * min(far.values()):.1f} - {100 * max(far.values()):.1f} %)")
    if max(err.values()) > 5.0:
        goals.append(f"median position error {min(err.values()):.2f} - {max(err.values()):.2f} % of slant distance on "
                     "the test seeds with ippe_lm (goal 5 %)")
    note = (f"validation (seeds {', '.join(val['seeds'])}, {val['n']} approaches): detection {100 * val['detection_rate']:.1f} %, nominal "
            f"survival {100 * val['survival_ippe_lm']:.1f} %; test seeds {', '.join(tests)}: survival "
            + ", ".join(f"{100 * v:.1f} %" for v in surv.values()) + "; see MODEL_CARD.md")
    return {"version": version, "trained_epochs": epochs, "note": note, "validated": bool(validated),
            "open_goals": goals}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint")
    ap.add_argument("--version", type=int, required=True)
    ap.add_argument("--epochs", type=int, required=True)
    ap.add_argument("--protocol", required=True)
    ap.add_argument("--against", default=None, help="the shipped model's protocol JSON (the replacement rule)")
    ap.add_argument("--force", action="store_true", help="ship even if the replacement rule is not met")
    args = ap.parse_args()
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.detect.train import ship

    setup_offline()
    with open(args.protocol) as f:
        protocol = json.load(f)
    if args.against is None and not args.force:
        raise SystemExit("ship_checkpoint: --against SHIPPED.json is required (the replacement rule); --force skips it")
    if args.against is not None:
        with open(args.against) as f:
            ok, why = replacement_verdict(protocol, json.load(f))
        print(f"replacement rule {'met' if ok else 'NOT met'}: {why}")
        if not ok and not args.force:
            raise SystemExit("ship_checkpoint: not shipped (the candidate cannot be told from the shipped model; "
                             "--force ships anyway)")
    info = info_from_protocol(protocol, args.version, args.epochs)
    print(json.dumps(info, indent=1))
    print(ship(args.checkpoint, detector="twostage", imgsz=320, info=info))


if __name__ == "__main__":
    main()
