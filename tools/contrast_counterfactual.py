"""What in the scene decides the far width error? Counterfactual re-renderings of the runway's surroundings.

For the far approaches of one protocol seed it renders every approach twice — as generated, and with one change
of the airport's painted layout (same pose, lighting, textures, markings, noise) — runs the two-stage detector on
both and prints, per airport: the runway − grass contrast, the shoulders, the near- and far-threshold width error
(mean over PCK-correct detections) and the survival, before and after. Changes (``--change``):

- ``grass`` — only the grass recoloured so that the runway surface stands ``--contrast`` in luminance off it
  (brighter grass around a dark runway, darker around a light one): does a faint runway edge cause the bias?
- ``no-shoulders`` — the paved shoulders removed (grass where they were): does the detector, unable to tell the
  runway's edge from the shoulder's, hedge between the two?

    python tools/contrast_counterfactual.py [--model PT [--min-side PX]] [--seed S] [--change grass|no-shoulders]
                                            [--contrast 0.25]
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from far_error_budget import _bias, _lum, edge_parts, protocol_args, runway_rows, surfaces  # noqa: E402


def recoloured_layout(layout_fn, contrast: float):
    """``layout_fn(airport)`` with row 0 (the grass) rescaled to luminance runway ± ``contrast``."""
    def layout(airport):
        rows = np.array(layout_fn(airport), copy=True)
        surf = rows[runway_rows(rows, airport)[0]]
        lr, lg = _lum(surf[8:11]), _lum(rows[0][8:11])
        target = lr + contrast if lr + contrast <= 0.95 else lr - contrast
        rows[0][8:11] = np.clip(rows[0][8:11] * (target / max(lg, 1e-3)), 0.0, 1.0)
        return rows
    return layout


def shoulderless_layout(layout_fn):
    """``layout_fn(airport)`` without the target runway's shoulders (:func:`runway_rows`)."""
    def layout(airport):
        rows = np.asarray(layout_fn(airport))
        return np.delete(rows, runway_rows(rows, airport)[1], axis=0)
    return layout


def run(det, samples, change: str | None, contrast: float):
    import importlib

    from vbl_robust.detect.evaluate import evaluate_detector

    gen = importlib.import_module("vbl_robust.scenes.generate")  # the module (the package exports the function)

    before = gen._layout
    if change == "grass":
        gen._layout = recoloured_layout(gen.airport_layout, contrast)
    elif change == "no-shoulders":
        gen._layout = shoulderless_layout(gen.airport_layout)
    try:
        for s in samples:  # render now, under the chosen layout (pixels are lazy)
            _ = s.image
        return evaluate_detector(det, samples)
    finally:
        gen._layout = before


def per_airport(samples, r) -> dict[str, list]:
    out = defaultdict(lambda: [0, 0, [], []])
    e = r.pos_err_m["ippe_lm"]
    for i, s in enumerate(samples):
        a = out[str(s.meta["airport"])]
        a[0] += 1
        a[1] += bool(e[i] <= 1000.0)
        if r.correct[i]:
            p, t = edge_parts(s.corners_2d + r.corner_delta[i] * (s.width / 1024.0)), edge_parts(s.corners_2d)
            a[2].append(np.log(p["near"][1] / t["near"][1]))
            a[3].append(np.log(p["far"][1] / t["far"][1]))
    return out


def main() -> None:
    from detector_protocol import detector

    ap = protocol_args(__doc__)
    ap.add_argument("--change", choices=("grass", "no-shoulders"), default="grass")
    ap.add_argument("--contrast", type=float, default=0.25, help="runway − grass luminance step of --change grass")
    args = ap.parse_args()
    from vbl_robust.detect.offline import setup_offline
    from vbl_robust.scenes import generate

    setup_offline()
    torch.set_num_threads(1)
    det = detector(args.model, **({"min_side": args.min_side} if args.min_side is not None else {}))
    paint = surfaces(args.seed)
    res = {}
    after = f"grass at contrast {args.contrast:g}" if args.change == "grass" else "no shoulders"
    for name, change in (("as generated", None), (after, args.change)):
        samples = [s for s in generate(args.n, seed=args.seed) if s.meta["envelope"] == "far"]
        r = run(det, samples, change, args.contrast)
        res[name] = per_airport(samples, r)
        n_ok = sum(v[1] for v in res[name].values())
        print(f"{name}: far survival {100 * n_ok / len(samples):.1f} % ({len(samples)} approaches)")
    (a_name, a), (b_name, b) = res.items()
    print(f"\n| airport | runway − grass contrast | shoulders (m) | near-edge width error: {a_name} | {b_name} "
          f"| far-edge: {a_name} | {b_name} | survival: {a_name} | {b_name} |\n|---|---|---|---|---|---|---|---|---|")
    for k in sorted(a):
        c, sw = paint[k]["contrast"], paint[k]["shoulder_m"]
        print(f"| {k} | {c:+.2f} | {f'{sw:.1f}' if sw else 'none'} | {_bias(a[k][2])} | {_bias(b[k][2])} | "
              f"{_bias(a[k][3])} | {_bias(b[k][3])} | {100 * a[k][1] / a[k][0]:.0f} % | {100 * b[k][1] / b[k][0]:.0f} % |")


if __name__ == "__main__":
    main()
