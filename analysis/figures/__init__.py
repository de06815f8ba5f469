"""Every figure of the analysis (matplotlib, Agg canvas, no pyplot): one run
(:mod:`.run_figures`), several runs overlaid (:mod:`.compare_figures`), the traffic around
the formation (:mod:`.traffic_figures`), a hand-over (:mod:`.handover_figures`), a sweep
(:mod:`.sweep_figures`); shared helpers in :mod:`.figure_kit`. The only part of the analysis
that imports matplotlib, and only when a figure is drawn.
"""
