"""Analysis of recorded formation-traci runs.

Reads only the recorded files (``run.json`` and Parquet tables) and never imports the
simulator: a run can be analysed on a machine without SUMO. Entry points:
:func:`analyze_run` and :func:`compare_runs` (see :mod:`analysis.api`), :func:`analyze_sweep`
(:mod:`analysis.report.sweep_report`); metric definitions are in ``docs/metrics.md``; the
layout: docs/architecture.md. Formation metrics: :mod:`analysis.metrics.formation`,
:mod:`analysis.metrics.comfort`, :mod:`analysis.metrics.iso2631`, :mod:`analysis.metrics.limits`;
traffic interaction (SSM, clearance, 2-D TTC, headways, baseline twin):
:mod:`analysis.metrics.traffic` (pure functions) and :mod:`analysis.runs.traffic_run` (per run).
"""
from analysis.api import AnalysisResult, CompareResult, NoTrajectoryData, analyze_run, compare_runs
from analysis.report.sweep_report import analyze_sweep

__all__ = ["AnalysisResult", "CompareResult", "NoTrajectoryData", "analyze_run",
           "compare_runs", "analyze_sweep"]
