"""Robustness campaigns: specs as data, a resumable SQLite results store, local and Ray executors, metrics.

>>> from vbl_robust.campaigns import EXPERIMENTS
>>> sorted(EXPERIMENTS)[:3]
['convergence', 'distance-profile', 'pnp-validation']

Typical use (what ``vbl-robust reproduce`` does)::

    spec = experiment("spatial-1d").build(seed, Options())
    samples, source = load_samples(100, seed)
    with ResultStore(out / "results.sqlite") as store:
        run_campaign(spec, samples, store, detector=DetectorSpec.auto(), dataset_source=source)
"""

from .experiments import EXPERIMENTS, Experiment, Options, audit_spec, experiment
from .export import export
from .metrics import (
    convergence,
    distance_profile,
    phi_crit,
    pnp_summary,
    reference_rows,
    smallest_breach_levels,
    summarize,
    survival_rate,
)
from .provenance import DetectorSpec, code_version, dataset_identity, file_sha256, sample_fingerprint
from .runner import EXECUTORS, Progress, RunSummary, plan, run_campaign
from .samples import find_lard_files, load_samples
from .spec import (
    EPS_SAFE_M,
    PENALTY_M,
    Block,
    BoxSpec,
    Budget,
    CampaignSpec,
    Job,
    roll_box,
    roll_contrast_box,
)
from .store import JobRow, JobStatus, Points, ResultStore

__all__ = [
    "EPS_SAFE_M",
    "EXECUTORS",
    "EXPERIMENTS",
    "PENALTY_M",
    "Block",
    "BoxSpec",
    "Budget",
    "CampaignSpec",
    "DetectorSpec",
    "Experiment",
    "Job",
    "JobRow",
    "JobStatus",
    "Options",
    "Points",
    "Progress",
    "ResultStore",
    "RunSummary",
    "audit_spec",
    "code_version",
    "convergence",
    "dataset_identity",
    "distance_profile",
    "experiment",
    "export",
    "file_sha256",
    "find_lard_files",
    "load_samples",
    "phi_crit",
    "plan",
    "pnp_summary",
    "reference_rows",
    "roll_box",
    "roll_contrast_box",
    "run_campaign",
    "sample_fingerprint",
    "smallest_breach_levels",
    "summarize",
    "survival_rate",
]
