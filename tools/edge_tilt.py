"""Edge-tilt slope and edge-width errors of a pose model on the crop views of a rendered YOLO-pose dataset.

The slope of the predicted on the labelled angle of the runway's threshold edges (TL→TR, BL→BR), by least
squares over the views where the model finds a candidate: 1 is a model that reads the edges' orientation, 0 one
that draws them level; then, per threshold edge, the slope of the predicted on the labelled log-width and the
median relative width error (the near edge's width is what decides a far approach's position).
``benchmarks/detector_protocol.py`` reports the same slope on held-out approaches; this
tool tells underfitting (low on the training views too) from a failure to generalise (low only held out).

    python tools/edge_tilt.py DATASET_DIR [--model PT] [--split train] [--n 300]

``DATASET_DIR`` is a directory written by ``vbl_robust.detect.train.build_dataset`` (views ``*_1`` are crops).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from vbl_robust.data.yolo import parse_pose_label
from vbl_robust.detect.evaluate import edge_angles_deg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--model", default=None, help="a trusted .pt (default: the shipped model)")
    ap.add_argument("--split", default="train")
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--imgsz", type=int, default=320)
    args = ap.parse_args()
    from vbl_robust.detect.offline import import_ultralytics
    from vbl_robust.detect.shipped import DEFAULT_MODEL

    torch.set_num_threads(1)
    import_ultralytics()
    from ultralytics import YOLO

    model = YOLO(str(args.model or DEFAULT_MODEL))
    labels = sorted((args.dataset / "labels" / args.split).glob("*_1.txt"))[: args.n]
    if not labels:
        raise SystemExit(f"edge_tilt: no crop labels (*_1.txt) under {args.dataset / 'labels' / args.split}")
    true, pred, widths = [], [], []
    for f in labels:
        _, corners, vis = parse_pose_label(f.read_text().splitlines()[0], args.imgsz, args.imgsz)
        if not vis.all():
            continue
        img = args.dataset / "images" / args.split / f"{f.stem}.png"
        res = model.predict(str(img), imgsz=args.imgsz, verbose=False, conf=0.1)[0]
        if res.keypoints is None or len(res.keypoints) == 0:
            continue
        k = res.keypoints.xy[int(res.boxes.conf.argmax())].numpy()
        true.append(edge_angles_deg(corners))
        pred.append(edge_angles_deg(k))
        widths.append([[np.linalg.norm(q[a] - q[b]) for a, b in ((0, 1), (3, 2))] for q in (corners, k)])
    t, p = np.array(true), np.array(pred)
    slope, icpt = np.polyfit(t, p, 1)
    print(f"{args.model or 'shipped model'} on {len(t)} {args.split} crops of {args.dataset.name}: edge-tilt slope "
          f"{slope:.3f} (intercept {icpt:+.2f}°), correlation {np.corrcoef(t, p)[0, 1]:.3f}; true angles "
          f"{np.percentile(t, 5):+.1f}° … {np.percentile(t, 95):+.1f}° (5–95 %)")
    w = np.log(np.array(widths))  # (N, true|pred, far|near edge)
    for j, name in enumerate(("far (TL-TR)", "near (BL-BR)")):
        err = np.abs(np.expm1(w[:, 1, j] - w[:, 0, j]))
        print(f"  {name} edge width: log-slope {np.polyfit(w[:, 0, j], w[:, 1, j], 1)[0]:.3f}, median |relative "
              f"error| {100 * np.median(err):.1f} %")


if __name__ == "__main__":
    main()
