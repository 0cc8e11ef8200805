"""Vulnerability-zone fractions of a stored run, per method and box, as a Markdown table (issue 16 measurement).

Every main search job of a covering method (DIRECT family, grid) is replayed on its stored values
(:func:`vbl_robust.zones.zones_of_run`: nothing is evaluated) and its cells classified breached / undecided /
ruled out. The table gives, per method and box (by level), the jobs, how many found a breach, and the mean % of Θ
in each class — over all jobs, and over the jobs that found no breach (those that spent their whole budget: the
cases where "ruled out" is the claim a certifier would want).

    python tools/zone_fractions.py runs/s1d30 --estimate          # GeoRobust's own slope estimate (not sound)
    python tools/zone_fractions.py runs/s1d30 --lipschitz 2000    # sound under L = 2000 m per unit (real units)
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np

from vbl_robust.zones import CLASSES, zones_of_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    basis = ap.add_mutually_exclusive_group(required=True)
    basis.add_argument("--estimate", action="store_true", help="classify under each search's own slope estimate")
    basis.add_argument("--lipschitz", type=float, help="classify soundly under this constant (2-norm, real units)")
    a = ap.parse_args()
    jobs = zones_of_run(a.run, roles=("main",), lipschitz=a.lipschitz, estimate=a.estimate)
    groups: dict[tuple[str, str], list] = defaultdict(list)
    skipped = defaultdict(int)
    for j in jobs:
        if j.zones is None:
            skipped[j.method] += 1
            continue
        groups[(j.method, j.box_label or "")].append(j)

    def width(label: str) -> float:  # boxes by size: the volume of the first job's box
        box = groups[next(k for k in groups if k[1] == label)][0].box
        return float(np.prod(np.asarray(box.upper) - np.asarray(box.lower)))

    basis_text = "estimate (not sound)" if a.estimate else f"sound under L = {a.lipschitz:g}"
    print(f"zones of {a.run}, main jobs, basis: {basis_text}; skipped (no cover): "
          + (", ".join(f"{m} {n}" for m, n in sorted(skipped.items())) or "none"))
    print()
    head = ["method", "box", "jobs", "breached jobs"] + [f"% {c.replace('_', ' ')}" for c in CLASSES]
    head += [f"% {c.replace('_', ' ')} (no-breach jobs)" for c in CLASSES if c != "breached"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for method, label in sorted(groups, key=lambda k: (k[0], width(k[1]))):
        js = groups[(method, label)]
        maps = [j.zones for j in js]
        hit = [zm.fractions["breached"] > 0 for zm in maps]
        row = [method, label, str(len(js)), str(sum(hit))]
        row += [f"{100 * np.mean([zm.fractions[c] for zm in maps]):.1f}" for c in CLASSES]
        clean = [zm for zm, h in zip(maps, hit, strict=True) if not h]
        row += [f"{100 * np.mean([zm.fractions[c] for zm in clean]):.1f}" if clean else "–"
                for c in CLASSES if c != "breached"]
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
