"""Rows of a fixed small audit, to show that a refactoring leaves behaviour unchanged.

The audit: 2 synthetic approaches (``generate(2, seed=0)``), roll ±15° × contrast [0.7, 1.4], GeoRobust /
random / APGD, 20 evaluations each, no early stop, seed 0 — on the shipped model (two-stage and single pass)
and on the oracle (1 px fixed corner noise). ``--write`` stores the rows in ``tests/golden/behaviour_rows.json``
(done once, on the code before a refactoring); ``tests/test_behaviour_golden.py`` recomputes and compares them.

    python tests/golden/behaviour_rows.py --write
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

GOLDEN = Path(__file__).resolve().parent / "behaviour_rows.json"
CONFIGS = ("twostage", "single", "oracle")
FIELDS = ("method", "sample_id", "worst_m", "worst_x", "nfev", "nit", "verdict", "search_status")


def audit_rows(config: str, n_samples: int = 2, max_evals: int = 20) -> list[dict]:
    """The rows of the fixed audit for one detector configuration, sorted by (sample, method)."""
    import torch

    from vbl_robust.campaigns.audit import audit_spec
    from vbl_robust.campaigns.runner import run_campaign
    from vbl_robust.detect.shipped import DetectorSpec
    from vbl_robust.scenes.generate import generate
    from vbl_robust.specs.budget import Budget
    from vbl_robust.specs.campaign import roll_contrast_box
    from vbl_robust.store.core import ResultStore

    torch.set_num_threads(1)
    det = DetectorSpec.oracle(1.0) if config == "oracle" else DetectorSpec("default", options={"design": config})
    spec = audit_spec(roll_contrast_box(15.0, (0.7, 1.4)), methods=("georobust", "random", "apgd"),
                      budget=Budget(max_evals=max_evals, stop_at_breach=False), seed=0)
    with tempfile.TemporaryDirectory() as d:
        store = ResultStore(Path(d) / "results.sqlite")
        run_campaign(spec, generate(n_samples, seed=0), store, detector=det)
        rows = [_plain_row(r) for r in store.jobs(role="main", with_trace=False)]
        store.close()
    return sorted(rows, key=lambda r: (r["sample_id"], r["method"]))


def _plain_row(r) -> dict:
    """The compared fields of a :class:`~vbl_robust.store.rows.JobRow`, as JSON values."""
    out = {k: getattr(r, k) for k in FIELDS}
    out["verdict"] = None if r.verdict is None else str(r.verdict.value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help=f"write {GOLDEN.name}")
    args = ap.parse_args()
    out = {c: audit_rows(c) for c in CONFIGS}
    text = json.dumps(out, indent=1, sort_keys=True)
    if args.write:
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        GOLDEN.write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
