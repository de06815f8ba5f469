"""One recorded run to metric tables: :func:`analysis.runs.summary.compute_run` picks the
rows and columns of a loaded run (:mod:`analysis.load`), handles damage and calls the pure
definitions of :mod:`analysis.metrics`: per member (:mod:`.member_metrics`,
:mod:`.member_comfort` over :mod:`.member_columns`), energy (:mod:`.energy`), traffic
(:mod:`.traffic_run` with :mod:`.interaction_run`, :mod:`.near_formation`,
:mod:`.conflict_run`, :mod:`.baseline_run`, :mod:`.twin_sections`); the tunable choices are
:mod:`.settings`. No file is written here.
"""
