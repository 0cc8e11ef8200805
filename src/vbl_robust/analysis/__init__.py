"""What a campaign's stored jobs say: metrics, survival tables, breach levels, the dense-grid reference, budgets
read off a trace, flat exports, and the truth behind "no breach found". These modules read a results store
(:mod:`vbl_robust.store`) and compute; they run no job.

Modules: :mod:`.breach` (per-job facts), :mod:`.summary` (survival tables), :mod:`.levels` (breach levels and the
perturbation families), :mod:`.reference` (the dense grid as the reference), :mod:`.readoff` (budgets read off a
trace), :mod:`.metrics` (the convergence of DIRECT-family traces, the PnP comparison), :mod:`.tables` (CSV /
Parquet exports), :mod:`.truth` (``vbl-robust truth``: the survivors' dense-grid campaign), :mod:`.risk` (a risk
run's pooled failure rate). Each name is imported from the module that defines it.
"""
