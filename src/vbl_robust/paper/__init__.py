"""The paper: its experiments, their verdicts and the bundle a reader of them gets, above the report that renders
one run.

Modules: :mod:`.experiments` (the paper's experiments as campaign specs, run by the engine: ``Options``,
``EXPERIMENTS``, ``PAPER`` and each experiment's builder), :mod:`.claims` (the paper's claims checked on the
results stores of ``reproduce paper``) with its rules (:mod:`.claim_rules`) and its pages (:mod:`.claims_page`),
:mod:`.detectors` (the claims with several detectors side by side), :mod:`.bundle` (``vbl-robust bundle``: reports,
claims, status and packed stores, small enough to commit), :mod:`.estimate` (``reproduce --estimate``: each
experiment's expected duration from a measured probe).
"""
