"""The detector's evaluation protocol (issue 14; seeds, gates and goals: :mod:`vbl_robust.detect.protocol`): a
validation set for every choice, test seeds for the figures.

- **Validation** (``VALIDATION_SEEDS``, 510 approaches each): the sets every choice is made on — checkpoints,
  schedules, data mixes — compared on their pooled rows. Seed 20261122 is the former benchmark set on which v5,
  v6 and v7 were chosen (v7 as the best of many checkpoints on it), so its figures carry that selection bias and
  are never quoted as a model's accuracy. Seed 20261202 was added on 2026-12-02, before any model was evaluated
  on it: one seed is only 10 airports, and checkpoints of the same recipe moved by ±4 points on it. Seeds
  20261203 and 20261204 were added on 2026-12-03 (session 13), before any model was evaluated on them, because
  the paired test on two seeds could not separate candidates 8–16 approaches apart (MODEL_CARD).
- **Test** (``TEST_SEEDS``, fixed on 2026-12-01 before step J's training ended; 510 approaches each, each seed its
  own pool of 10 airports): the figures of the model card and BENCHMARKS.md, reported per seed and per envelope
  with the spread over seeds. No choice is ever made on them.

Each set: the shipped design (two-stage 320 + 320, ``ippe_lm`` and ``iterative`` PnP; ``--design single``: the
network alone on the 320-px view), no perturbation;
detection at τ_conf = 0.25, nominal survival (position error ≤ 1000 m), median position error in % of the slant
distance, the edge-tilt slope (predicted on true threshold-edge angle; 1 = reads the roll,
:func:`vbl_robust.detect.evaluate.edge_tilt_slope`), per envelope. Gates (every test seed): detection ≥ 97 %, survival ≥ 90 %; goals: detection ≥ 98 %,
survival ≥ 95 % (far ≥ 90 %), median error ≤ 5 % of slant.

    python benchmarks/detector_protocol.py [--model PATH.pt] [--split validation|test|all] [--n 510]
                                           [--seeds S ...] [--json OUT.json] [--min-side PX] [--margin M]
                                           [--second PASS2.pt] [--design twostage|single] [--compare OTHER.json]

Rendered pixels are cached in ``.cache/bench_detector/seed<S>`` (shared with ``bench_detector.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import time

import torch

from vbl_robust.detect.protocol import GATES, GOALS, TEST_SEEDS, VALIDATION_SEEDS

VALIDATION_SEED = VALIDATION_SEEDS[0]  # the first validation seed (older tools' default)


def detector(model: str | None, second: str | None = None, design: str = "twostage", **window):
    """The shipped two-stage detector, or ``model`` (a trusted .pt) as one with crop ``window`` (``min_side``,
    ``margin``: what its training crops used); ``second``: a trusted .pt for pass 2 (a crop network of its own,
    ``train(full_views=False)``), pass 1 staying ``model`` (or the shipped weights). ``design="single"``: the
    network (``model`` or the shipped one) as a single pass on the 320-px view instead — no crop, so neither
    ``second`` nor a window."""
    from vbl_robust.detect.shipped import DEFAULT_MODEL, default_detector, with_design
    from vbl_robust.detect.twostage import TwoStageDetector
    from vbl_robust.detect.ultralytics import UltralyticsDetector

    if design == "single":
        if second is not None or window:
            raise SystemExit("detector_protocol: --design single has no pass 2: drop --second/--min-side/--margin")
        return with_design(UltralyticsDetector(model or DEFAULT_MODEL, trust=True, imgsz=320), "single")
    if model is None and second is None:
        if window:
            raise ValueError("detector_protocol: --min-side/--margin apply to --model, not to the shipped model")
        return default_detector(design="twostage")
    first = UltralyticsDetector(model or DEFAULT_MODEL, trust=True, imgsz=320)
    if second is None:
        return with_design(first, "twostage", **window)
    return TwoStageDetector(first, UltralyticsDetector(second, trust=True, imgsz=320), **window)


def evaluate(det, seed: int, n: int) -> tuple[list[dict], list[bool]]:
    """The summary rows of one seed and, per approach, whether it survived (ippe_lm) for paired comparisons."""
    from bench_detector import held_out
    from vbl_robust.detect.evaluate import SURVIVAL_M, evaluate_detector, range_rows

    r = evaluate_detector(det, held_out(n, seed))
    return range_rows(r), [bool(e <= SURVIVAL_M) for e in r.pos_err_m["ippe_lm"]]


def compare(new: dict, old: dict, split: str = "validation") -> str:
    """Paired comparison of two protocol JSONs (``--json``) on the approaches of ``split`` both evaluated:
    per seed and pooled, the approaches only one model survives and the exact McNemar p-value
    (:func:`vbl_robust.stats.paired`)."""
    from vbl_robust.detect.evaluate import paired_seeds

    designs = [d.get("design", "twostage") for d in (new, old)]  # files written before --design: two-stage
    if designs[0] != designs[1]:
        raise SystemExit(f"detector_protocol: --compare pairs one design with itself, not {designs[0]} with "
                         f"{designs[1]}")
    try:
        rows, pooled = paired_seeds(new, old, split)
    except ValueError as exc:
        raise SystemExit(f"detector_protocol: {exc}") from None
    lines = ["| seed | n | both survive | only new | only old | neither | new − old | p (exact McNemar) |",
             "|---|---|---|---|---|---|---|---|"]
    for s, c in rows + [("pooled", pooled)]:
        lines.append(f"| {s} | {c.n} | {c.both} | {c.only_a} | {c.only_b} | {c.neither} | {c.gain:+d} | "
                     f"{c.p_value:.4f} |")
    return "\n".join(lines)


def table(results: dict[int, list[dict]]) -> str:
    lines = ["| seed | envelope | n | detection | survival ippe_lm | survival iterative | pos. err % slant ippe_lm "
             "| pos. err % slant iterative | corner median (px) | edge tilt |", "|---|---|---|---|---|---|---|---|---|---|"]
    for seed, rows in results.items():
        for r in rows:
            lines.append(f"| {seed} | {r['envelope']} | {r['n']} | {100 * r['detection_rate']:.1f} % | "
                         f"{100 * r['survival_ippe_lm']:.1f} % | {100 * r['survival_iterative']:.1f} % | "
                         f"{r['pos_err_pct_ippe_lm']:.2f} | {r['pos_err_pct_iterative']:.2f} | "
                         f"{r['corner_median_px']:.2f} | {r.get('edge_tilt_slope', float('nan')):.2f} |")
    return "\n".join(lines)


def pooled(results: dict[int, list[dict]]) -> str:
    """The approach-weighted mean over seeds of detection, survival and the far survival (the validation row
    every choice compares)."""
    def mean(env, key):
        rows = [next(r for r in rs if r["envelope"] == env) for rs in results.values()]
        return sum(r[key] * r["n"] for r in rows) / sum(r["n"] for r in rows)

    n = sum(next(r for r in rs if r["envelope"] == "all")["n"] for rs in results.values())
    return (f"Pooled over {len(results)} seed(s), {n} approaches: detection {100 * mean('all', 'detection_rate'):.1f} %, "
            f"survival {100 * mean('all', 'survival_ippe_lm'):.1f} % (far {100 * mean('far', 'survival_ippe_lm'):.1f} "
            f"%, medium {100 * mean('medium', 'survival_ippe_lm'):.1f} %, close "
            f"{100 * mean('close', 'survival_ippe_lm'):.1f} %).")


def spread(results: dict[int, list[dict]]) -> str:
    """min – max over seeds of the 'all' and 'far' rows, and the gates/goals verdicts."""
    def pick(env, key):
        return [next(r for r in rows if r["envelope"] == env)[key] for rows in results.values()]

    det, surv = pick("all", "detection_rate"), pick("all", "survival_ippe_lm")
    far, err = pick("far", "survival_ippe_lm"), pick("all", "pos_err_pct_ippe_lm")
    gates = min(det) >= GATES["detection_rate"] and min(surv) >= GATES["survival_ippe_lm"]
    goals = {"detection ≥ 98 %": min(det) >= GOALS["detection_rate"],
             "survival ≥ 95 %": min(surv) >= GOALS["survival_ippe_lm"],
             "far survival ≥ 90 %": min(far) >= GOALS["far_survival_ippe_lm"],
             "median error ≤ 5 % of slant": max(err) <= GOALS["pos_err_pct_ippe_lm"]}
    return (f"Over seeds (min – max): detection {100 * min(det):.1f} – {100 * max(det):.1f} %, survival "
            f"{100 * min(surv):.1f} – {100 * max(surv):.1f} % (far {100 * min(far):.1f} – {100 * max(far):.1f} %), "
            f"median position error {min(err):.2f} – {max(err):.2f} % of slant. Gates on every seed: "
            f"{'met' if gates else 'NOT met'}; goals: "
            + ", ".join(f"{k} {'met' if v else 'open'}" for k, v in goals.items()) + ".")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="a trusted .pt (default: the shipped model)")
    ap.add_argument("--split", choices=("validation", "test", "all"), default="all")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="only these seeds of the split (e.g. the new validation seed for models measured before)")
    ap.add_argument("--n", type=int, default=510)
    ap.add_argument("--json", default=None)
    ap.add_argument("--min-side", type=float, default=None, help="crop window of --model (its training crops')")
    ap.add_argument("--margin", type=float, default=None, help="crop margin of --model (its training crops')")
    ap.add_argument("--compare", default=None,
                    help="a previous --json of another model: paired comparison (approaches only one survives, "
                         "exact McNemar p) on the seeds both evaluated")
    ap.add_argument("--second", default=None, help="a trusted .pt for pass 2 (crop network; pass 1: --model)")
    ap.add_argument("--design", choices=("twostage", "single"), default="twostage",
                    help="the shipped two-stage design (default) or the network alone as a single pass")
    args = ap.parse_args()
    from vbl_robust.detect.offline import setup_offline

    setup_offline()
    torch.set_num_threads(int(os.environ.get("VBL_BENCH_THREADS", "1")))
    window = {k: v for k, v in (("min_side", args.min_side), ("margin", args.margin)) if v is not None}
    det = detector(args.model, args.second, design=args.design, **window)
    seeds = {"validation": VALIDATION_SEEDS, "test": TEST_SEEDS,
             "all": (*VALIDATION_SEEDS, *TEST_SEEDS)}[args.split]
    if args.seeds:
        unknown = sorted(set(args.seeds) - set(seeds))
        if unknown:
            raise SystemExit(f"detector_protocol: --seeds {unknown} not in the {args.split} split {list(seeds)}")
        seeds = tuple(args.seeds)
    out: dict[str, dict] = {}
    survived: dict[str, list[bool]] = {}
    t0 = time.perf_counter()
    for split, group in (("validation", [s for s in seeds if s in VALIDATION_SEEDS]),
                         ("test", [s for s in seeds if s in TEST_SEEDS])):
        if not group:
            continue
        both = {s: evaluate(det, s, args.n) for s in group}
        res = {s: rows for s, (rows, _) in both.items()}
        out[split] = {str(s): rows for s, rows in res.items()}
        survived.update({str(s): alive for s, (_, alive) in both.items()})
        print(f"### {split} ({args.model or 'shipped model'}{f' + pass 2 {args.second}' if args.second else ''}, {det!r}, {args.n} approaches per seed)\n")
        print(table(res) + "\n")
        print(pooled(res) + "\n")
        if split == "test":
            print(spread(res) + "\n")
    print(f"({time.perf_counter() - t0:.0f} s, {torch.get_num_threads()} torch thread(s))")
    result = {"model": args.model or "shipped", "second": args.second, "design": args.design, "n": args.n, **out,
              "survived": survived}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    if args.compare:
        with open(args.compare) as f:
            old = json.load(f)
        for split in ("validation", "test"):
            if split in out and split in old:
                print(f"\n### paired: this model (new) against {old.get('model')}"
                      f"{' + ' + old['second'] if old.get('second') else ''} (old), {split}\n")
                print(compare(result, old, split))


if __name__ == "__main__":
    main()
