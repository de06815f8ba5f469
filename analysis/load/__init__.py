"""Reading a recorded run directory: ``run.json`` and the Parquet tables, each problem an
:class:`~analysis.load.run_files.Issue` instead of an exception (:mod:`.run_files`), the
formation's members and their slots (:mod:`.run_members`), the whole run as a
:class:`~analysis.load.run_data.RunData` (:mod:`.run_data`). Imports nothing of the analysis
but :func:`analysis.metrics.formation.offsets_in_vc_frame` (slots inferred from a record).
"""
