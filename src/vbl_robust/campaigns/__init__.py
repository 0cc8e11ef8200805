"""Robustness campaigns, the engine: the ``audit`` / ``risk`` jobs as specs (:mod:`.audit`), the runner (local,
Ray) and its jobs, verification, replay and refinement of stored searches, hardening. Below it: the specs
(:mod:`vbl_robust.specs`) and the results store (:mod:`vbl_robust.store`); above it: what reads a store
(:mod:`vbl_robust.analysis`, :mod:`vbl_robust.report`, :mod:`vbl_robust.paper`) and the paper's experiments
(:mod:`vbl_robust.paper.experiments`), which the engine runs as it runs an audit.

>>> from vbl_robust.campaigns.audit import audit_spec
>>> from vbl_robust.specs.budget import Budget
>>> from vbl_robust.specs.campaign import roll_box
>>> [b.methods for b in audit_spec(roll_box(5), budget=Budget(max_evals=10)).blocks]
[('georobust-av', 'random', 'apgd')]

Typical use (what ``vbl-robust reproduce`` does; ``ResultStore`` from :mod:`vbl_robust.store`, ``experiment`` and
``Options`` from :mod:`vbl_robust.paper.experiments`)::

    spec = experiment("spatial-1d").build(seed, Options())
    samples, source = load_samples(100, seed)
    with ResultStore(out / "results.sqlite") as store:
        run_campaign(spec, samples, store, detector=DetectorSpec.auto(), dataset_source=source)

Names are resolved lazily, as in :mod:`vbl_robust`: importing a light submodule (the audit's spec, for the command
line's help) does not import torch.
"""

from __future__ import annotations

from vbl_robust.lazy import lazy_names

#: public name -> the submodule that defines it
_LAZY: dict[str, str] = {
    "DetectorSpec": "vbl_robust.detect.shipped",
    "run_campaign": ".runner",
    "load_samples": ".samples",
    "zones_of_run": ".replay",
}

__all__ = sorted(_LAZY)  # every public name is lazy: listed once, in _LAZY


__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals(), __all__)
