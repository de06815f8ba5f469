"""``metrics.json``: the document :func:`analysis.api.analyze_run` writes, built from a
:class:`~analysis.runs.summary.RunAnalysis`, and the conversion of the analysis' values to
plain JSON (docs/outputs.md, docs/metrics.md).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import Issue
from analysis.metrics.maneuvers import PHASE_METRICS, maneuver_intervals, phase_metrics
from analysis.runs.fleet import FORMATION_METRICS
from analysis.runs.summary import MEMBER_METRICS, RUN_METRICS, RunAnalysis, settings_dict
from analysis.runs.traffic_run import TRAFFIC_RUN_METRICS, TrafficAnalysis

__all__ = ["SCHEMA", "jsonable", "records", "issues_frame", "metrics_doc"]

SCHEMA = "formation-traci/metrics/1"
"""Identifier of the ``metrics.json`` layout."""


def jsonable(x: Any) -> Any:
    """``x`` as plain JSON values: dict keys as text, tuples and arrays as lists, paths as text,
    numpy scalars as Python ones, NaN, infinities and pandas' NA as None.

    Parameters
    ----------
    x : Any
        A value of the analysis (nested dicts, lists, numpy and pandas values).

    Returns
    -------
    Any
        The same value, JSON-ready.
    """
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if x is pd.NA or x is pd.NaT:
        return None
    return x


def records(df: pd.DataFrame) -> list[dict[str, Any]]:
    """The rows of ``df`` as JSON-ready dicts (its index left out).

    Parameters
    ----------
    df : DataFrame
        A table of the analysis.

    Returns
    -------
    list of dict
        One dict per row, column name to :func:`jsonable` value.
    """
    return [jsonable(r) for r in df.to_dict(orient="records")]


def issues_frame(issues: Sequence[Issue], run: str | None = None) -> pd.DataFrame:
    """The issues as a table.

    Parameters
    ----------
    issues : sequence of Issue
        The issues of a run.
    run : str, optional
        A run label, written as a first column ``run``.

    Returns
    -------
    DataFrame
        Columns (``run``,) ``severity``, ``kind``, ``what``, ``detail``.
    """
    cols = ["severity", "kind", "what", "detail"]
    df = pd.DataFrame([i.as_dict() for i in issues], columns=cols)
    if run is not None:
        df.insert(0, "run", run)
    return df


def _traffic_json(t: TrafficAnalysis | None) -> dict[str, Any] | None:
    if t is None:
        return None
    base = None
    if t.baseline is not None:
        base = records(t.baseline.reset_index())
    return {
        "run": jsonable(t.run),
        "units": TRAFFIC_RUN_METRICS,
        "ssm": {g: jsonable(r.to_dict()) for g, r in t.ssm.iterrows()},
        "member_conflicts": records(t.member_conflicts),
        "ssm_extremes": records(t.ssm_extremes),
        "conflicts": records(t.conflicts),
        "baseline_vehicles": base,
        "unavailable": dict(t.unavailable),
    }


def _maneuvers_json(a) -> dict[str, Any]:
    """Maneuver intervals and the steady / maneuver split of error and comfort per member."""
    traj = a.data.trajectories
    t_end = float(traj["t"].max()) if len(traj) else 0.0
    iv = maneuver_intervals(a.data.tables.get("events"), t_end)
    if iv.empty:
        return {"intervals": [], "phases": [], "units": PHASE_METRICS}
    ph = phase_metrics(traj, [m.id for m in a.data.members], iv, a.data.dt)
    return {"intervals": records(iv), "phases": records(ph.reset_index()), "units": PHASE_METRICS}


def _fleet_json(a: RunAnalysis) -> dict[str, Any]:
    """A run of several formations: each formation's formation-level metrics and the
    fleet's (analysis/runs/fleet.py); nothing for a run of one formation."""
    if a.fleet is None:
        return {}
    return {"formation_metrics": a.fleet.formations, "fleet": a.fleet.fleet}


def metrics_doc(a: RunAnalysis, run_dir: Path, issues: Sequence[Issue],
                fig_paths: dict[str, Path], out: Path) -> dict[str, Any]:
    """The content of ``metrics.json``.

    Parameters
    ----------
    a : RunAnalysis
        The run's analysis (:func:`analysis.runs.fleet.compute_formations`).
    run_dir : Path
        The run directory.
    issues : sequence of Issue
        Every issue of the run, those found while writing included.
    fig_paths : dict of str to Path
        The figures written, by name.
    out : Path
        The output directory (figures are named relative to it).

    Returns
    -------
    dict
        The document (values JSON-ready after :func:`jsonable`); with several formations
        also ``formation_metrics`` (formation id to its formation-level metrics) and
        ``fleet`` (their mean and worst over the formations).
    """
    settings = a.settings
    members_json = []
    for mid, row in a.members.iterrows():
        rec = {"id": mid, **row.to_dict(), "unavailable": a.unavailable.get(mid, {})}
        members_json.append(jsonable(rec))
    traj = a.data.trajectories
    doc = {
        "schema": SCHEMA,
        "run_dir": str(run_dir),
        "run": a.run,
        "members": members_json,
        "string_stability": records(a.string_stability),
        "formations": list(a.formations),  # formation level: string_amplification (docs/metrics.md)
        **_fleet_json(a),
        "issues": [i.as_dict() for i in issues],
        "damaged": any(i.severity == "error" for i in issues),
        "tables": {
            "trajectories": {"rows": len(traj),
                             "vehicles": sorted(map(str, traj["vehicle_id"].unique())),
                             "missing_columns": sorted(a.data.missing_columns)},
            **{k: (None if v is None else {"rows": len(v)}) for k, v in a.data.tables.items()},
        },
        "meta": a.data.meta if a.fleet is None else a.fleet.meta,
        "settings": settings_dict(settings),
        "units": {"run": RUN_METRICS, "members": MEMBER_METRICS,
                  **({} if a.fleet is None else {"formation_metrics": FORMATION_METRICS})},
        "traffic": _traffic_json(a.traffic),
        "comm_age": records(a.comm_age) if a.comm_age is not None else [],
        "maneuvers": _maneuvers_json(a),
        # per formation: what the ramp vehicles at the route's joins did (run.json merges)
        "merges": ((a.data.meta.get("merges") or {}).get("by_formation")) or {},
        "figures": {k: str(p.relative_to(out)) for k, p in fig_paths.items()},
    }
    return doc
