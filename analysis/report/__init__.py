"""What the analysis writes for a reader: one run's or several runs' HTML report
(:mod:`.run_report`) and its verdicts and headline numbers (:mod:`.headline`); a sweep's
metric table (:mod:`.sweep_metrics`), its paired effects over seeds (:mod:`.effects`) and its
page (:mod:`.sweep_report` ``analyze_sweep``).
"""
