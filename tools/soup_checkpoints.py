"""Average the weights of trusted pose checkpoints ("model soup") into one checkpoint, for the detector protocol.

Each input's EMA weights are used when present (what ultralytics evaluates), else its model; the average is taken
in float32 and stored, like a stripped ultralytics checkpoint, as fp16 ``model`` without optimizer or EMA. The
files are unpickled: pass only checkpoints you trust (your own training runs, the shipped model).

    python tools/soup_checkpoints.py OUT.pt A.pt B.pt [C.pt ...]
"""

from __future__ import annotations

import copy
import sys

import torch

from vbl_robust.detect.offline import import_ultralytics


def main(out: str, paths: list[str]) -> None:
    import_ultralytics()
    ckpts = [torch.load(p, weights_only=False, map_location="cpu") for p in paths]  # trusted: see the docstring
    models = [(c.get("ema") or c["model"]).float() for c in ckpts]
    states = [m.state_dict() for m in models]
    avg = {k: (sum(s[k] for s in states) / len(states)) if states[0][k].is_floating_point() else states[0][k]
           for k in states[0]}
    soup = copy.deepcopy(models[0])
    soup.load_state_dict(avg)
    base = dict(ckpts[0])
    base.update(model=soup.half(), ema=None, optimizer=None, updates=None, epoch=-1,
                train_results={"soup_of": paths})
    torch.save(base, out)
    print(f"{out}: average of {len(paths)} checkpoints")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2:])
