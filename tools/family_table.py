"""The perturbation families' ranking of a ``reproduce families`` run as a Markdown table (issue 15 measurement).

The same profile, ranking and rows as the report's families section (:func:`vbl_robust.report.build.family_lines`:
survival % per level and method, the dense grid's reference and the "any method" series, and the level where
survival drops below 50 % and 10 %), read from the run's store; nothing is evaluated. Only images whose every job
is stored count, so a run still in progress gives a consistent table.

    python tools/family_table.py runs/families30
    python tools/family_table.py runs/families30 --series any     # only the combined series (the ranking's basis)
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from vbl_robust.campaigns import metrics as mx
from vbl_robust.campaigns.spec import CampaignSpec
from vbl_robust.campaigns.store import ResultStore
from vbl_robust.report import build as B


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--series", choices=("all", "any"), default="all")
    a = ap.parse_args()
    with ResultStore.open_existing(a.run) as store:
        spec = CampaignSpec.from_dict(store.campaign()["spec"])
        main_rows = mx.main_rows(store, spec)
        ctx = B.Context(store, spec, Path(a.run), main_rows, store.samples())
        ref = B._reference(ctx, B._main_boxes(ctx))
    per_image_main = len({(r.method, r.box_label) for r in main_rows})
    counts: dict[str, int] = {}
    for r in main_rows:
        counts[r.sample_id] = counts.get(r.sample_id, 0) + 1
    ref_counts: dict[str, int] = {}
    for r in ref:
        ref_counts[r.sample_id] = ref_counts.get(r.sample_id, 0) + 1
    ref_full = max(ref_counts.values(), default=0)
    done = {s for s, n in counts.items() if n == per_image_main and (not ref or ref_counts.get(s, 0) == ref_full)}
    rows = [r for r in main_rows if r.sample_id in done and mx.family_of(r) is not None]
    ref = [r for r in ref if r.sample_id in done]
    profile = mx.family_profile(rows + ref, spec.eps_safe_m)
    order = mx.rank_families(profile)
    lines = B.family_lines(profile, order)
    if a.series == "any":
        lines = [ln for ln in lines if ln["method"] == B.F.style(mx.ANY_METHOD)["label"]]
    print(f"{a.run}: {len(done)} complete images of {len(counts)} started; reference rows per image {ref_full}; "
          f"ranking (most vulnerable first): {', '.join(order)}")
    print()
    ks = [k for k in lines[0] if k.startswith("L") and k[1:].isdigit()] if lines else []
    head = ["rank", "family", "method", "images", *[f"{k} %" for k in ks], "< 50 % at", "< 10 % at"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for ln in lines:
        vals = ["–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.0f}" for v in
                (ln[k] for k in ks)]
        print("| " + " | ".join([str(ln["rank"]), ln["family"], ln["method"], str(ln["n"]), *vals,
                                 ln["below_50"], ln["below_10"]]) + " |")


if __name__ == "__main__":
    main()
