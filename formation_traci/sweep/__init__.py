"""Parameter studies: a sweep file expands into cases, each run in its own process.

``expand_sweep(path)`` lists the cases, ``run_sweep(path, out_dir, ...)`` runs them (a local
pool or a Dask cluster; resumable) into ``out_dir/summary.parquet``. Plotting them is
analysis's job: ``analysis.report.sweep_report.analyze_sweep(out_dir)``. See docs/sweeps.md.

Names are imported on first use, so the case process (``python -m
formation_traci.sweep.case``) loads only what it needs.
"""
from __future__ import annotations

import importlib

_EXPORTS = {
    "Case": "expand", "Sweep": "expand", "expand_sweep": "expand", "load_sweep": "expand",
    "CaseSpec": "case", "run_case": "case",
    "METRICS": "row",
    "SweepResult": "run", "run_sweep": "run",
    "SweepError": "spec",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
