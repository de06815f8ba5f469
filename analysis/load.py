"""Robust loading of a recorded run directory.

A run directory holds ``run.json`` and Parquet tables (``trajectories.parquet`` and, for
SUMO runs, ``background.parquet``, ``events.parquet``, ``ssm.parquet``), each either a
dataset directory of part files or a single file. Loading never fails on damage: every
problem becomes an :class:`Issue` and whatever is readable is returned. Only a run with
no readable trajectory rows at all raises :class:`NoTrajectoryData`.
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

import formation_traci.record.columns as _contract
from formation_traci.record.columns import TRAJECTORY_COLUMNS, VIRTUAL_CAR_ID

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
    "describe_issues",
]

RUN_JSON = "run.json"
TRAJECTORIES = "trajectories.parquet"
OPTIONAL_TABLES = ("background", "events", "ssm", "comfort")
"""Tables written by SUMO runs only (``comfort``: every run since it was introduced, the
members' accelerations at the control rate); their absence is reported as information."""

REQUIRED_META_KEYS = ("status", "reason", "t_end", "record_step", "model", "mu", "members",
                      "scenario")
ANALYSED_COLUMNS = frozenset({
    "t", "vehicle_id", "x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "ex", "ey",
    "e_lon", "e_lat", "x_des", "y_des", "v_ref", "omega_ref", "slip_front", "slip_rear",
    "traction_force", "traction_force_max", "friction_usage"})
"""Trajectory columns some metric or figure uses; any other contract column missing from a
recording (e.g. the road/SUMO-only ``s``, ``d``, ``lane_index``) is reported as info only."""

TABLE_CONTRACTS = {"background": "BACKGROUND_COLUMNS", "events": "EVENT_COLUMNS",
                   "ssm": "SSM_COLUMNS", "comfort": "COMFORT_COLUMNS"}
"""Names of the column contracts of the optional tables in ``formation_traci.record.columns``
(checked when the contract exists)."""

GAP_FACTOR = 1.5
"""A time step larger than ``GAP_FACTOR * record_step`` is a gap in the record [-]."""

_FLOAT_COLUMNS = tuple(c.name for c in TRAJECTORY_COLUMNS if c.dtype == "float64")


class NoTrajectoryData(RuntimeError):
    """The run has no readable trajectory rows: nothing can be analysed."""


class DamagedPartWarning(RuntimeWarning):
    """Some Parquet part files could not be read and were skipped."""


@dataclass(frozen=True, slots=True)
class Issue:
    """One thing missing or damaged in a run, or one caveat of the analysis."""

    severity: str  # "error" (data lost/damaged), "warning" (result caveat), "info"
    kind: str  # short machine-readable category, e.g. "corrupt_part"
    what: str  # the file, key, column or member concerned
    detail: str  # human-readable explanation

    def as_dict(self) -> dict[str, str]:
        """Plain-dict form for JSON.

        Returns
        -------
        dict
            Keys ``severity``, ``kind``, ``what``, ``detail``.
        """
        return {"severity": self.severity, "kind": self.kind, "what": self.what,
                "detail": self.detail}


def describe_issues(issues) -> str:
    """One line counting the run's data issues by severity, the same in the CLI and the report.

    Parameters
    ----------
    issues : iterable
        :class:`Issue` objects or dicts with a ``severity``.

    Returns
    -------
    str
        e.g. ``"3 data issue(s): 0 error(s), 1 warning(s), 2 note(s)"``.
    """
    sev = [i["severity"] if isinstance(i, dict) else getattr(i, "severity", None) for i in issues]
    return (f"{len(sev)} data issue(s): {sev.count('error')} error(s), {sev.count('warning')} "
            f"warning(s), {sev.count('info')} note(s)")


@dataclass(frozen=True, slots=True)
class Member:
    """A formation member as declared in ``run.json`` (or inferred)."""

    id: str
    offset: tuple[float, float]  # m, (d_x, d_y) of eq. 2.4
    frame: str  # "vehicle" | "road" | "inferred"


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


def _part_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    files = []
    for p in sorted(path.rglob("*")):
        rel = p.relative_to(path).parts
        if p.is_file() and not any(s.startswith((".", "_")) for s in rel):
            files.append(p)
    return files


def read_table(path: str | Path, name: str | None = None) -> tuple[pd.DataFrame | None, list[Issue]]:
    """Read a Parquet dataset directory (or single file), skipping unreadable parts.

    Parameters
    ----------
    path : str or Path
        Dataset directory of part files, or one Parquet file. Files and directories
        whose name starts with ``.`` or ``_`` are ignored, as pyarrow does.
    name : str, optional
        Name used in issues; default the path's name.

    Returns
    -------
    (DataFrame or None, list of Issue)
        The concatenated rows of every readable part (None if there are none) and the
        problems met: missing table, empty dataset, unreadable parts (each listed).
        Unreadable parts also raise a :class:`DamagedPartWarning`.
    """
    path = Path(path)
    name = name or path.name
    if not path.exists():
        return None, [Issue("info", "missing_table", name, f"{path.name} does not exist")]
    parts = _part_files(path)
    if not parts:
        return None, [Issue("error", "empty_table", name, f"{path.name} has no part files")]
    frames, bad, issues = [], [], []
    for p in parts:
        try:
            frames.append(pq.read_table(p).to_pandas())
        except Exception as exc:  # noqa: BLE001 - any reader failure means a damaged part
            rel = p.relative_to(path.parent)
            bad.append(str(rel))
            issues.append(Issue("error", "corrupt_part", str(rel),
                                f"unreadable, skipped ({type(exc).__name__}: "
                                f"{str(exc).splitlines()[0][:200] if str(exc) else ''})"))
    if bad:
        warnings.warn(f"{name}: skipped {len(bad)} unreadable part file(s): {', '.join(bad)}",
                      DamagedPartWarning, stacklevel=2)
    frames = [f for f in frames if len(f.columns)]
    if not frames:
        return None, issues
    union = set().union(*(f.columns for f in frames))
    partial = sorted(c for c in union if any(c not in f.columns for f in frames))
    if partial:
        issues.append(Issue("error", "schema_mismatch", name,
                            f"column(s) {', '.join(partial)} absent from some part files; "
                            "their rows there are NaN"))
    df = pd.concat(frames, ignore_index=True, sort=False) if len(frames) > 1 else frames[0]
    return df, issues


def read_meta(run_dir: str | Path) -> tuple[dict[str, Any], list[Issue]]:
    """Read and check ``run.json``.

    Parameters
    ----------
    run_dir : str or Path
        Run directory.

    Returns
    -------
    (dict, list of Issue)
        The parsed content (``{}`` when missing or unreadable) and the problems found:
        missing or invalid file, missing keys of :data:`REQUIRED_META_KEYS`, run status
        other than ``"completed"``.
    """
    p = Path(run_dir) / RUN_JSON
    if not p.is_file():
        return {}, [Issue("error", "missing_file", RUN_JSON,
                          "run.json is missing: status, model, mu, record_step and member "
                          "offsets are unknown; they are inferred from the trajectories "
                          "where possible")]
    try:
        meta = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return {}, [Issue("error", "invalid_file", RUN_JSON, f"unreadable: {exc}")]
    if not isinstance(meta, dict):
        return {}, [Issue("error", "invalid_file", RUN_JSON,
                          f"top level is {type(meta).__name__}, expected an object")]
    issues = [Issue("error", "missing_meta_key", f"{RUN_JSON}:{k}", f"key '{k}' is missing")
              for k in REQUIRED_META_KEYS if k not in meta]
    status = meta.get("status")
    if status is not None and status != "completed":
        why = {"interrupted": "the run was interrupted",
               "failed": "the run failed",
               "running": "the run has not finished (or died without writing its status)"}
        issues.append(Issue("warning", "run_status", f"{RUN_JSON}:status",
                            f"status '{status}': {why.get(status, 'unknown status')}"
                            + (f"; reason: {meta.get('reason')}" if meta.get("reason") else "")))
    return meta, issues


def _members_from_meta(meta: dict[str, Any]) -> tuple[list[Member], list[Issue]]:
    raw = meta.get("members")
    if raw is None:
        return [], []
    if not isinstance(raw, list):
        return [], [Issue("error", "invalid_meta", f"{RUN_JSON}:members", "not a list")]
    out, issues = [], []
    for k, m in enumerate(raw):
        try:
            mid = str(m["id"])
            off = tuple(float(v) for v in m["offset"])
            if len(off) != 2 or not all(math.isfinite(v) for v in off):
                raise ValueError("offset must be two finite numbers")
            frame = str(m.get("frame", "vehicle"))
            if "frame" not in m:
                issues.append(Issue("warning", "missing_meta_key",
                                    f"{RUN_JSON}:members[{k}].frame",
                                    "frame missing, assumed 'vehicle'"))
            out.append(Member(mid, (off[0], off[1]), frame))
        except (KeyError, TypeError, ValueError) as exc:
            issues.append(Issue("error", "invalid_meta", f"{RUN_JSON}:members[{k}]",
                                f"unusable member entry {m!r}: {exc}"))
    return out, issues


def _infer_offset(traj: pd.DataFrame, mid: str) -> tuple[float, float] | None:
    from analysis.formation import offsets_in_vc_frame

    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "x", "y", "heading"]]
    me = traj.loc[traj["vehicle_id"] == mid, ["t", "x_des", "y_des"]]
    j = me.merge(vc, on="t").dropna()
    if j.empty:
        return None
    dx, dy = offsets_in_vc_frame(j["x_des"], j["y_des"], j["x"], j["y"], j["heading"])
    return float(np.median(dx)), float(np.median(dy))


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
    if t[0] > (GAP_FACTOR * dt if math.isfinite(dt) else 0.0):
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
    run_dir = Path(run_dir)
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

    dt, dt_issues = _sample_spacing(traj, meta)
    issues += dt_issues
    issues += _coverage_issues(traj, dt, meta)

    members, m_issues = _members_from_meta(meta)
    issues += m_issues
    ids_data = [v for v in pd.unique(traj["vehicle_id"]) if v != VIRTUAL_CAR_ID]
    if VIRTUAL_CAR_ID not in set(traj["vehicle_id"]):
        issues.append(Issue("error", "missing_vehicle", VIRTUAL_CAR_ID,
                            "no virtual-car rows: its path is not drawn and offsets cannot "
                            "be inferred"))
    declared = {m.id for m in members}
    twin = meta.get("baseline") is True
    for m in members:
        if m.id not in set(ids_data):
            issues.append(Issue("info", "baseline_run", m.id,
                                "baseline twin run: the formation is not driven, so the "
                                "member has no rows by design") if twin else
                          Issue("error", "missing_vehicle", m.id,
                                "member declared in run.json has no trajectory rows"))
    if "members" not in meta or not members:
        for mid in ids_data:
            off = _infer_offset(traj, mid)
            if off is not None:
                members.append(Member(mid, off, "inferred"))
        if ids_data:
            issues.append(Issue("warning", "members_inferred", "members",
                                "member list taken from the trajectories; offsets inferred "
                                "from x_des/y_des and the virtual-car pose (eq. 2.4)"
                                if members else
                                "member list taken from the trajectories; offsets unknown"))
        known = {m.id for m in members}
        members += [Member(mid, (math.nan, math.nan), "unknown") for mid in ids_data
                    if mid not in known]
    else:
        for mid in ids_data:
            if mid not in declared:
                issues.append(Issue("warning", "undeclared_vehicle", mid,
                                    "vehicle in the trajectories but not in run.json members; "
                                    "analysed without a declared offset"))
                off = _infer_offset(traj, mid)
                members.append(Member(mid, off if off else (math.nan, math.nan),
                                      "inferred" if off else "unknown"))

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
    return RunData(run_dir=run_dir, meta=meta, trajectories=traj, dt=dt,
                   members=tuple(members), missing_columns=missing, tables=tables,
                   issues=tuple(issues))
