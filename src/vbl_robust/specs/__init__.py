"""A campaign as data: what the engine runs (:mod:`vbl_robust.campaigns`), the store records
(:mod:`vbl_robust.store`) and the analysis and the report read.

Modules: :mod:`.campaign` (:class:`~.campaign.CampaignSpec`: blocks of boxes × methods × budgets, expanded into
:class:`~.campaign.Job` s; :class:`~.campaign.BoxSpec`, the report's figures), :mod:`.settings`
(:class:`~.settings.PipelineSettings`: what every job of a campaign shares), :mod:`.budget`
(:class:`~.budget.Budget`: evaluations, time, early stop), :mod:`.kinds` (the vocabularies of jobs, rows and runs:
:class:`~.kinds.JobKind`, :class:`~.kinds.JobStatus`, :class:`~.kinds.Role`, :class:`~.kinds.RunStatus`, …).
"""
