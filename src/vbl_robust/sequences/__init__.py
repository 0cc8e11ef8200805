"""Sequence audits: one perturbation θ held over the frames of an approach, and the error it sustains.

A filter downstream of the pose estimate rides out one bad frame, not a perturbation that lasts. For an
:class:`~vbl_robust.data.sequence.ApproachSequence` and a box Θ, :class:`~.objective.SequenceObjective` scores θ by
the error sustained over ``k`` consecutive frames (:func:`~.sustain.sustained`), callable by every method of
:func:`vbl_robust.search.maximize` (a torch θ takes the differentiable path APGD needs);
:func:`~.sustain.breach_summary` gives the breach runs and where along the approach they start (the report draws
the per-frame errors against distance: :func:`vbl_robust.report.sequence_figure.plot_errors_along_approach`).

Modules: :mod:`.objective` (the objective and its per-frame records), :mod:`.sustain` (the sustained error and the
breach runs).

>>> import vbl_robust as vr                                                                # doctest: +SKIP
>>> from vbl_robust.scenes.sequences import generate_sequences                             # doctest: +SKIP
>>> from vbl_robust.sequences.objective import SequenceObjective
>>> seq = generate_sequences(1, frames=20, rate_hz=10.0, seed=0)[0]                        # doctest: +SKIP
>>> box = vr.ParameterBox({"roll_deg": (-15, 15)})                                          # doctest: +SKIP
>>> f = SequenceObjective(seq, vr.OracleDetector(noise_px=1.0), box, sustain=10)            # doctest: +SKIP
>>> r = vr.search.maximize(f, box, "georobust", max_evals=60)                              # doctest: +SKIP
>>> f.evaluate(r.x[None]).summary(0)["longest_run_frames"]                                 # doctest: +SKIP
"""
