"""What metric ``georobust-a`` ended with on each stored job of a run (issue 17 analysis; nothing is evaluated).

Each main ``georobust-a`` job is replayed on its stored values (:func:`vbl_robust.zones.replay`) and the
method's own per-dimension slope estimates read back: the upper quartile of the slopes seen along each dimension
(unit cube, metres per unit), their ratio to the largest, and the final offsets of the metric
(:meth:`~vbl_robust.search.adaptive.AdaptiveGeoRobust.metric_offsets`; 0 everywhere = classic GeoRobust's division,
ratios below ``MIN_RATIO`` fall in the dead zone).

    python tools/metric_offsets.py runs/issue17_spatial2d
"""

from __future__ import annotations

import argparse
from collections import Counter

import numpy as np

from vbl_robust.campaigns.spec import CampaignSpec
from vbl_robust.campaigns.store import ResultStore
from vbl_robust.search.adaptive import MIN_RATIO, QUANTILE
from vbl_robust.zones import replay


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--method", default="georobust-a")
    a = ap.parse_args()
    with ResultStore.open_existing(a.run) as store:
        spec = CampaignSpec.from_dict(store.campaign()["spec"])
        rows = [r for r in store.jobs(kind="search", role="main", with_points=True, with_trace=False)
                if r.method == a.method and r.points is not None and len(r.points)]
    if not rows:
        raise SystemExit(f"{a.run}: no stored {a.method} jobs")
    names = rows[0].box.box.names
    ratios, offsets = [], Counter()
    for r in rows:
        opt = replay(r, spec)
        q = np.array([np.quantile(s, QUANTILE) if s else np.nan for s in opt._slopes])
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios.append(np.nanmax(q) / q)
        offsets[tuple(int(o) for o in opt.metric_offsets())] += 1
    ratios = np.array(ratios)
    print(f"{a.run}: {len(rows)} {a.method} jobs; dimensions {', '.join(names)}; dead zone below {MIN_RATIO:g}")
    for i, n in enumerate(names):
        v = ratios[:, i]
        print(f"  {n}: largest slope / this one's — median {np.nanmedian(v):.3g}, quartiles "
              f"{np.nanquantile(v, 0.25):.3g}–{np.nanquantile(v, 0.75):.3g}; jobs at ≥ {MIN_RATIO:g}: "
              f"{np.mean(v >= MIN_RATIO):.0%}")
    print("  final offsets (count of jobs): " + ", ".join(f"{k}: {c}" for k, c in offsets.most_common()))


if __name__ == "__main__":
    main()
