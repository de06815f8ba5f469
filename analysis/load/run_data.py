"""Robust loading of a recorded run directory.

A run directory holds ``run.json`` and Parquet tables (``trajectories.parquet`` and, for
SUMO runs, ``background.parquet``, ``events.parquet``, ``ssm.parquet``), each either a
dataset directory of part files or a single file. Loading never fails on damage: every
problem becomes an :class:`Issue` and whatever is readable is returned. Only a run with
no readable trajectory rows at all raises :class:`NoTrajectoryData`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import run_contract.columns as _contract
from analysis.load.run_files import (REQUIRED_META_KEYS, RUN_JSON, TRAJECTORIES, DamagedPartWarning,
                                     Issue, describe_issues, read_meta, read_table)
from analysis.load.run_members import Member, run_members
from run_contract.columns import TRAJECTORY_COLUMNS, VIRTUAL_CAR_ID

__all__ = [
    "RUN_JSON",
    "TRAJECTORIES",
    "OPTIONAL_TABLES",
    "REQUIRED_META_KEYS",
    "ANALYSED_COLUMNS",
    "TABLE_CONTRACTS",
    "GAP_FACTOR",
    "Issue",
    "Member",
    "RunData",
    "NoTrajectoryData",
    "DamagedPartWarning",
    "read_table",
    "read_meta",
    "load_run",
    "load_formations",
    "formation_ids",
    "describe_issues",
]

OPTIONAL_TABLES = ("background", "events", "ssm", "comfort")
"""Tables written by SUMO runs only (``comfort``: every run since it was introduced, the
members' accelerations at the control rate); their absence is reported as information."""

ANALYSED_COLUMNS = frozenset({
    "t", "vehicle_id", "x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "ex", "ey",
    "e_lon", "e_lat", "x_des", "y_des", "v_ref", "omega_ref", "slip_front", "slip_rear",
    "traction_force", "traction_force_max", "friction_usage"})
"""Trajectory columns some metric or figure uses; any other contract column missing from a
recording (e.g. the road/SUMO-only ``s``, ``d``, ``lane_index``) is reported as info only."""

TABLE_CONTRACTS = {"background": "BACKGROUND_COLUMNS", "events": "EVENT_COLUMNS",
                   "ssm": "SSM_COLUMNS", "comfort": "COMFORT_COLUMNS"}
"""Names of the column contracts of the optional tables in ``run_contract.columns``
(checked when the contract exists)."""

GAP_FACTOR = 1.5
"""A time step larger than ``GAP_FACTOR * record_step`` is a gap in the record [-]."""

_FLOAT_COLUMNS = tuple(c.name for c in TRAJECTORY_COLUMNS if c.dtype == "float64")


class NoTrajectoryData(RuntimeError):
    """The run has no readable trajectory rows: nothing can be analysed."""



@dataclass(frozen=True)
class RunData:
    """Everything read from a run directory."""

    run_dir: Path
    meta: dict[str, Any]  # run.json content ({} if missing/unreadable)
    trajectories: pd.DataFrame  # sorted by vehicle_id, t; every contract column present
    dt: float  # s, sample spacing actually used
    members: tuple[Member, ...]  # formation members (never the virtual car)
    missing_columns: frozenset[str]  # contract columns absent from every readable part
    tables: dict[str, pd.DataFrame | None]  # optional tables, None when absent/unreadable
    issues: tuple[Issue, ...] = field(default_factory=tuple)


def _sample_spacing(traj: pd.DataFrame, meta: dict[str, Any]) -> tuple[float, list[Issue]]:
    issues = []
    t = np.unique(traj["t"].to_numpy(dtype=float))
    steps = np.diff(t)
    steps = steps[steps > 0]
    inferred = float(np.median(steps)) if steps.size else math.nan
    declared = meta.get("record_step")
    try:
        declared = float(declared) if declared is not None else math.nan
    except (TypeError, ValueError):
        issues.append(Issue("error", "invalid_meta", f"{RUN_JSON}:record_step",
                            f"not a number: {declared!r}"))
        declared = math.nan
    if math.isfinite(declared) and declared > 0:
        if math.isfinite(inferred) and abs(inferred - declared) > 1e-6 * max(declared, 1e-9) + 1e-9:
            issues.append(Issue("warning", "record_step_mismatch", f"{RUN_JSON}:record_step",
                                f"run.json says {declared:g} s, the trajectories are spaced "
                                f"{inferred:g} s; using {inferred:g} s"))
            return inferred, issues
        return declared, issues
    if math.isfinite(inferred):
        if "record_step" in meta:
            issues.append(Issue("warning", "record_step_inferred", "record_step",
                                f"record_step unusable, inferred {inferred:g} s from the data"))
        return inferred, issues
    issues.append(Issue("error", "record_step_unknown", "record_step",
                        "a single time sample and no record_step: rates cannot be computed"))
    return math.nan, issues


def _coverage_issues(traj: pd.DataFrame, dt: float, meta: dict[str, Any]) -> list[Issue]:
    issues: list[Issue] = []
    t = np.unique(traj["t"].to_numpy(dtype=float))
    if t.size == 0:
        return issues
    begin = float(meta.get("t_begin") or 0.0)  # a formation that entered later (run.json formations)
    if t[0] > begin + (GAP_FACTOR * dt if math.isfinite(dt) else 0.0):
        issues.append(Issue("error", "missing_head", TRAJECTORIES,
                            f"trajectories start at {t[0]:g} s instead of 0 s: the first "
                            "part(s) are missing"))
    if not math.isfinite(dt):
        return issues
    steps = np.diff(t)
    gaps = np.nonzero(steps > GAP_FACTOR * dt)[0]
    if gaps.size:
        spans = ", ".join(f"{t[g]:g}-{t[g + 1]:g} s" for g in gaps[:10])
        more = f" and {gaps.size - 10} more" if gaps.size > 10 else ""
        lost = float(np.sum(steps[gaps] - dt))
        issues.append(Issue("error", "time_gap", TRAJECTORIES,
                            f"{gaps.size} gap(s) in the record ({spans}{more}), "
                            f"{lost:g} s missing; derivative and filter metrics are computed "
                            "per contiguous segment"))
    t_end = meta.get("t_end")
    if isinstance(t_end, (int, float)) and math.isfinite(t_end):
        if t[-1] < t_end - GAP_FACTOR * dt:
            issues.append(Issue("error", "truncated_tail", TRAJECTORIES,
                                f"trajectories end at {t[-1]:g} s but run.json t_end is "
                                f"{t_end:g} s: {t_end - t[-1]:g} s missing"))
    return issues


def load_run(run_dir: str | Path) -> RunData:
    """Load a run directory, reporting instead of failing on damage.

    A run of several formations (``[[formations]]``) is loaded as its first formation, with
    a warning naming the others; :func:`load_formations` gives every formation.

    Parameters
    ----------
    run_dir : str or Path
        Run directory containing ``run.json`` and ``trajectories.parquet``.

    Returns
    -------
    RunData
        Metadata, trajectories (float columns coerced to float64, ``vehicle_id`` to str,
        rows without time or id dropped, duplicates ``(vehicle_id, t)`` dropped keeping
        the last, contract columns missing from the data added as NaN and listed in
        ``missing_columns``), sample spacing, members, optional tables and issues.

    Raises
    ------
    NoTrajectoryData
        If no trajectory row can be read (missing table, every part unreadable, or the
        ``t``/``vehicle_id`` columns absent).
    """
    views = load_formations(run_dir)
    first, data = next(iter(views.items()))
    if len(views) == 1:
        return data
    warn = Issue("warning", "several_formations", "formation_id",
                 f"the run has {len(views)} formations ({', '.join(views)}); this analysis "
                 f"covers formation '{first}' only")
    return replace(data, issues=(*data.issues, warn))


def load_formations(run_dir: str | Path) -> dict[str, RunData]:
    """Load a run directory as one :class:`RunData` per formation, each as if that formation
    had run alone: its rows (``formation_id``), its virtual car as ``'vc'``, its members in
    ``meta["members"]``; the optional tables are shared.

    Parameters
    ----------
    run_dir : str or Path
        Run directory containing ``run.json`` and ``trajectories.parquet``.

    Returns
    -------
    dict of str to RunData
        Formation id to its data, in the order of run.json's members (the top-level
        formation ``f0`` first); one entry for a run of one formation (the same data as
        :func:`load_run`; ``f0`` when the record has no ``formation_id``).

    Raises
    ------
    NoTrajectoryData
        As :func:`load_run`.
    """
    run_dir = Path(run_dir)
    meta, traj, missing, issues = _read_trajectories(run_dir)
    tables, tab_issues = _optional_tables(run_dir)
    fids = formation_ids(traj, meta)
    views: dict[str, RunData] = {}
    for fid in fids:
        f_traj, f_meta = (_formation_view(traj, meta, fid) if len(fids) > 1
                          else (traj, formation_times(meta, fid)))
        dt, dt_issues = _sample_spacing(f_traj, f_meta)
        cov_issues = _coverage_issues(f_traj, dt, f_meta)
        members, m_issues = run_members(f_meta, f_traj)
        views[fid] = RunData(run_dir=run_dir, meta=f_meta, trajectories=f_traj, dt=dt,
                             members=tuple(members), missing_columns=missing, tables=tables,
                             issues=tuple(issues + dt_issues + cov_issues + m_issues
                                          + tab_issues))
    return views


def _read_trajectories(run_dir: Path):
    """run.json and the cleaned trajectories of every formation, with their issues."""
    if not run_dir.is_dir():
        raise NoTrajectoryData(f"{run_dir} is not a directory")
    issues: list[Issue] = []
    meta, meta_issues = read_meta(run_dir)
    issues += meta_issues

    traj, t_issues = read_table(run_dir / TRAJECTORIES, TRAJECTORIES)
    issues += [i if i.kind != "missing_table" else
               Issue("error", "missing_table", TRAJECTORIES, i.detail) for i in t_issues]
    if traj is None or traj.empty:
        why = "; ".join(f"{i.what}: {i.detail}" for i in t_issues) or "no rows"
        raise NoTrajectoryData(f"{run_dir}: no trajectory data to analyse ({why})")
    for key in ("t", "vehicle_id"):
        if key not in traj.columns:
            raise NoTrajectoryData(f"{run_dir}: trajectories have no '{key}' column; "
                                   "rows cannot be placed in time or attributed to a vehicle")
    traj, missing, c_issues = _clean_trajectories(traj, run_dir)
    return meta, traj, missing, issues + c_issues


def _clean_trajectories(traj: pd.DataFrame,
                        run_dir: Path) -> tuple[pd.DataFrame, frozenset[str], list[Issue]]:
    """Trajectories in contract form: missing contract columns added as NaN (and listed),
    float columns coerced, rows without time or id and duplicate ``(vehicle_id, t)`` rows
    dropped, sorted by vehicle and time."""
    issues: list[Issue] = []
    missing = frozenset(c.name for c in TRAJECTORY_COLUMNS if c.name not in traj.columns)
    for c in TRAJECTORY_COLUMNS:
        if c.name in missing and c.name in ANALYSED_COLUMNS:
            issues.append(Issue("error", "missing_column", c.name,
                                f"column '{c.name}' ({c.doc}) is absent; metrics that need "
                                "it are not computed"))
        elif c.name in missing:
            issues.append(Issue("info", "missing_column", c.name,
                                f"column '{c.name}' ({c.doc}) is absent; not used by the "
                                "analysis"))
    traj = traj.copy()
    for name in _FLOAT_COLUMNS:
        if name in traj.columns:
            traj[name] = pd.to_numeric(traj[name], errors="coerce").astype("float64")
        else:
            traj[name] = np.nan
    for name in _FLOAT_COLUMNS:  # inf is damage, not a value: treated as missing, counted
        inf = np.isinf(traj[name].to_numpy())
        if inf.any():
            issues.append(Issue("error", "non_finite_values", name,
                                f"{int(inf.sum())} infinite value(s) in column '{name}'; treated as "
                                "missing (the rest is computed)"))
            traj.loc[inf, name] = np.nan
    bad = traj["t"].isna() | traj["vehicle_id"].isna()
    traj["vehicle_id"] = traj["vehicle_id"].astype(str)
    bad |= traj["vehicle_id"].isin(["", "nan", "None", "<NA>"])
    if bad.any():
        issues.append(Issue("error", "invalid_rows", TRAJECTORIES,
                            f"{int(bad.sum())} rows without time or vehicle id dropped"))
        traj = traj.loc[~bad]
    n0 = len(traj)
    traj = traj.drop_duplicates(["vehicle_id", "t"], keep="last")
    if len(traj) < n0:
        issues.append(Issue("warning", "duplicate_rows", TRAJECTORIES,
                            f"{n0 - len(traj)} duplicate (vehicle_id, t) rows dropped, "
                            "last kept"))
    if traj.empty:
        raise NoTrajectoryData(f"{run_dir}: no valid trajectory rows")
    contract = [c.name for c in TRAJECTORY_COLUMNS]
    extra = [c for c in traj.columns if c not in contract]
    traj = traj[contract + extra].sort_values(["vehicle_id", "t"], kind="stable")
    traj = traj.reset_index(drop=True)

    return traj, missing, issues


def formation_ids(traj: pd.DataFrame, meta: dict[str, Any]) -> list[str]:
    """The formations of a run: the ``formation_id`` of run.json's members in their order,
    then any other id in the trajectories; ``["f0"]`` (the top-level formation's id) when
    the record has no ``formation_id``.

    Parameters
    ----------
    traj : DataFrame
        The run's trajectories.
    meta : dict
        run.json's content.

    Returns
    -------
    list of str
        Formation ids, the first formation first.
    """
    if "formation_id" not in traj.columns:
        return ["f0"]
    declared = [m.get("formation_id") for m in meta.get("members") or []
                if isinstance(m, dict)]
    recorded = pd.unique(traj["formation_id"].astype(str))
    fids = [f for f in dict.fromkeys([*declared, *recorded])
            if isinstance(f, str) and f and f in set(recorded)]
    return fids or ["f0"]


def _formation_view(traj: pd.DataFrame, meta: dict[str, Any], fid: str):
    """Formation ``fid``'s rows, its virtual car ('vc:<fid>') as 'vc', its members in run.json."""
    traj = traj.loc[traj["formation_id"].astype(str) == fid].copy()
    traj.loc[traj["vehicle_id"] == f"{VIRTUAL_CAR_ID}:{fid}", "vehicle_id"] = VIRTUAL_CAR_ID
    meta = dict(meta, members=[m for m in meta.get("members", [])
                               if isinstance(m, dict) and m.get("formation_id", fid) == fid])
    return traj.reset_index(drop=True), formation_times(meta, fid)


def formation_times(meta: dict[str, Any], fid: str) -> dict[str, Any]:
    """``meta`` with formation ``fid``'s own record span (run.json ``formations``): ``t_begin``
    when it entered the road later, ``t_end`` when it was retired at the end of its route."""
    when = (meta.get("formations") or {}).get(fid) or {}
    if when.get("entered_s") is None and when.get("left_s") is None:
        return meta
    meta = dict(meta)
    if when.get("entered_s") is not None:
        meta["t_begin"] = float(when["entered_s"])
    if when.get("left_s") is not None:
        meta["t_end"] = float(when["left_s"])
    return meta


def _optional_tables(run_dir: Path) -> tuple[dict[str, pd.DataFrame | None], list[Issue]]:
    """The optional tables (None when absent or unreadable) and their issues."""
    issues: list[Issue] = []
    tables: dict[str, pd.DataFrame | None] = {}
    for name in OPTIONAL_TABLES:
        df, tab_issues = read_table(run_dir / f"{name}.parquet", f"{name}.parquet")
        tables[name] = df
        issues += tab_issues
        contract = getattr(_contract, TABLE_CONTRACTS[name], ())
        absent = [c.name for c in contract if df is not None and c.name not in df.columns]
        if absent:
            issues.append(Issue("warning", "missing_column", f"{name}.parquet",
                                f"column(s) {', '.join(absent)} absent"))
    return tables, issues
