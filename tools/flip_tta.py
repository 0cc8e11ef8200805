"""Mirror test-time augmentation of the crop pass: is the far width error noise (averaging helps) or systematic?

Runs the shipped two-stage design (or ``--model``) with pass 2 applied to the crop *and* to its mirror image
(corners swapped by ``flip_idx`` = TR↔TL, BL↔BR and mirrored back), the two corner sets averaged, on one protocol
seed, and prints the protocol's table. Twice the pass-2 cost; an experiment, not a shipped design.

Session 11 (v7, validation seed 20261122): survival 92.7 % (far 87.1 %) against 93.1 % (far 87.1 %) without —
averaging over the mirror does not move the far error: it is systematic (``tools/far_error_budget.py``).

    python tools/flip_tta.py [--model PATH.pt] [--seed 20261122] [--n 510]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

#: keypoint order TR, TL, BL, BR under a horizontal flip
FLIP_IDX = [1, 0, 3, 2]


def mirrored(base):
    """``base`` (a :class:`~vbl_robust.detect.TwoStageDetector`) with mirror-averaged pass-2 corners."""
    from vbl_robust.detect.base import as_context
    from vbl_robust.detect.pose import Top, split_raw
    from vbl_robust.detect.twostage import TwoStageDetector
    from vbl_robust.perturb.views import view_to_image

    class MirrorAveraged(TwoStageDetector):
        def top(self, context):
            ctx = as_context(context)
            t1 = self.first.top(ctx)
            s2 = self.second
            win = self.crop_windows(t1.keypoints, ctx.height, ctx.width)
            views = ctx.views(win, s2.imgsz)
            corners = []
            for flip in (False, True):
                _, conf, kp = split_raw(s2.raw_chunked(views.flip(-1) if flip else views), s2.nc)
                k = kp.gather(1, conf.argmax(1)[:, None, None, None].expand(-1, 1, 4, 2))[:, 0]
                if flip:  # view-pixel edge coordinates: x → size − x
                    k = k[:, FLIP_IDX].clone()
                    k[..., 0] = s2.imgsz - k[..., 0]
                corners.append(k)
            return Top(t1.conf, view_to_image((corners[0] + corners[1]) / 2, win, s2.imgsz), t1.boxes)

    return MirrorAveraged(base.first, base.second, margin=base.margin, min_side=base.min_side)


def main() -> None:
    import detector_protocol as dp

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="a trusted .pt (default: the shipped model)")
    ap.add_argument("--seed", type=int, default=dp.VALIDATION_SEED)
    ap.add_argument("--n", type=int, default=510)
    args = ap.parse_args()
    from vbl_robust.detect.offline import setup_offline

    setup_offline()
    torch.set_num_threads(1)
    rows = dp.evaluate(mirrored(dp.detector(args.model)), args.seed, args.n)
    print(dp.table({args.seed: rows}) + "\n\n" + dp.pooled({args.seed: rows}))


if __name__ == "__main__":
    main()
