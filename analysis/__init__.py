"""Analysis of recorded formation-traci runs.

Reads only the recorded files (``run.json`` and Parquet tables) and never imports the
simulator: a run can be analysed on a machine without SUMO. Entry points:
:func:`analyze_run` and :func:`compare_runs` (see :mod:`analysis.api`); metric
definitions are in ``docs/metrics.md``. Formation metrics: :mod:`analysis.formation`,
:mod:`analysis.comfort`, :mod:`analysis.iso2631`, :mod:`analysis.limits`; traffic
interaction (SSM, clearance, 2-D TTC, headways, baseline twin): :mod:`analysis.traffic`
(pure functions) and :mod:`analysis.traffic_run` (per run).
"""
from analysis.api import (AnalysisResult, CompareResult, NoTrajectoryData, analyze_run,
                          compare_runs)

__all__ = ["AnalysisResult", "CompareResult", "NoTrajectoryData", "analyze_run",
           "compare_runs"]
