"""One summary row per case: identity, swept values, status and the sweep metrics.

The metrics condense ``analysis.analyze_run`` (docs/metrics.md) over the members, so one
number per run can be plotted against the swept values; docs/sweeps.md lists them.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.report.sweep_metrics import EFFECT_KEYS, METRICS  # noqa: F401 (re-exported)

ID_COLUMNS: tuple[str, ...] = ("case_id", "case_index", "seed")
STATUS_COLUMNS: tuple[str, ...] = ("status", "reason", "t_end_s", "twin_status", "twin_reason")
"""A case's outcome; ``twin_status`` / ``twin_reason``: its twin's (sweeps with twins; None without)."""
WALL_COLUMNS: tuple[str, ...] = ("wall_s", "host", "pid")
"""Columns that depend on the machine and the clock, not on the case (ignored in comparisons)."""


COUNT_METRICS = frozenset({"n_unsettled", "collisions", "member_collisions", "member_removed",
                           "stranded", "sumo_collision_artefacts", "emergency_brakes", "requested_veh", "inserted_veh",
                           "comm_timeouts", "conflicts_ttc", "conflicts_ttc_formation", "conflicts_drac",
                           "conflicts_drac_formation", "law_fallbacks"})


def empty_row(case: dict, status: str, reason: str | None) -> dict[str, Any]:
    """A row with the case's identity and values and every metric missing.

    Parameters
    ----------
    case : dict
        ``Case.model_dump(mode="json")``.
    status : str
        ``completed``, ``completed_with_incidents``, ``failed`` or ``interrupted``.
    reason : str or None
        Why not completed.

    Returns
    -------
    dict
        Every summary column, metrics None.
    """
    row: dict[str, Any] = {"case_id": case["id"], "case_index": case["index"], "seed": case["seed"],
                           **case["values"], "status": status, "reason": reason, "t_end_s": None,
                           "twin_status": None, "twin_reason": None}
    row.update({k: None for k in METRICS})
    row.update({k: None for k in WALL_COLUMNS})
    return row


def _col(members: pd.DataFrame, name: str) -> np.ndarray:
    if name not in members:
        return np.full(len(members), np.nan)
    return pd.to_numeric(members[name], errors="coerce").to_numpy(dtype=float)


def _max(x: np.ndarray) -> float | None:
    x = x[~np.isnan(x)]
    return float(np.max(x)) if x.size else None


def _all_or_none(x: np.ndarray, fn) -> float | None:
    return float(fn(x)) if x.size and np.isfinite(x).all() else None


def _sumo_metrics(run_dir: Path, member_ids: set[str], meta: dict) -> dict[str, Any]:
    from analysis.load.run_data import read_table  # skips damaged parts, never raises

    events, _ = read_table(run_dir / "events.parquet")
    n_coll = 0
    if events is not None and len(events):
        c = events[events["kind"] == "collision"]
        n_coll = int((c["vehicle_id"].isin(member_ids) | c["other_id"].isin(member_ids)).sum())
    ssm, _ = read_table(run_dir / "ssm.parquet")
    ttc = None
    if ssm is not None and len(ssm):
        x = pd.to_numeric(ssm.loc[ssm["member_involved"].astype(bool), "min_ttc"], errors="coerce")
        ttc = float(x.min()) if x.notna().any() else None
    traffic = meta.get("traffic") or {}
    flows = (traffic.get("flows") or {}).values()
    measured = traffic.get("measured") or {}
    counts = meta.get("event_counts") or {}
    return {"collisions": n_coll, "min_ttc_s": ttc,
            "emergency_brakes": int(counts.get("emergency_brake", 0)),
            "comm_timeouts": int(counts.get("comm_timeout", 0)),
            "requested_veh": sum(int(f["requested"]) for f in flows) if flows else None,
            "inserted_veh": sum(int(f["inserted"]) for f in flows) if flows else None,
            "flow_measured_veh_h": measured.get("flow_veh_h"),
            "density_measured_veh_km": measured.get("density_veh_km")}


def _energy_metrics(members: pd.DataFrame) -> dict[str, Any]:
    """Formation energy from the members' analysis/runs/energy.py columns (sums, not means)."""
    e, d = _col(members, "traction_energy_kwh"), _col(members, "distance_km")
    alone = _col(members, "energy_alone_kwh_per_100km") * d / 100.0
    ok = np.isfinite(e) & np.isfinite(d)
    out: dict[str, Any] = {"energy_kwh_per_100km": None, "energy_saving_vs_alone": None}
    if ok.any() and d[ok].sum() > 0:
        out["energy_kwh_per_100km"] = float(e[ok].sum() / d[ok].sum() * 100.0)
        if np.isfinite(alone[ok]).all() and alone[ok].sum() > 0:
            out["energy_saving_vs_alone"] = float(1.0 - e[ok].sum() / alone[ok].sum())
    return out


def twin_values(traffic_run: dict) -> dict[str, Any]:
    """The paired columns of a case analysed against its twin (``traffic.run`` of its
    metrics.json): ``stretch_coverage``, ``matched_share`` and the ``fx_*`` effects.

    Parameters
    ----------
    traffic_run : dict
        ``metrics.json["traffic"]["run"]``.

    Returns
    -------
    dict
        Column -> float or None.
    """
    out = {k: traffic_run.get(k) for k in ("stretch_coverage", "matched_share")}
    out.update({col: traffic_run.get(key) for col, key in EFFECT_KEYS.items()})
    return {k: (None if v is None else float(v)) for k, v in out.items()}


def metric_values(run_dir: Path, members: pd.DataFrame, meta: dict,
                  formations=()) -> dict[str, Any]:
    """The :data:`METRICS` of one analysed run.

    Parameters
    ----------
    run_dir : Path
        Run directory (for the SUMO tables).
    members : DataFrame
        ``AnalysisResult.members``: one row per member.
    meta : dict
        ``run.json`` content.
    formations : sequence of dict
        The analysis' formation records (metrics.json ``formations``: ``min_gap_m``).

    Returns
    -------
    dict
        Metric name -> float, int or None (not available).
    """
    gaps = [f["min_gap_m"] for f in formations if f.get("min_gap_m") is not None]
    ts = _col(members, "settling_time_s")
    above = sum(np.nan_to_num(_col(members, f"t_lat_{b}_s"))
                for b in ("medium", "uncomfortable", "beyond"))
    out: dict[str, Any] = {
        "e_rms_m": _max(_col(members, "e_rms_m")),
        "e_max_settled_m": _all_or_none(_col(members, "e_max_settled_m"), np.max),
        "e_rms_settled_m": _all_or_none(_col(members, "e_rms_settled_m"),
                                        lambda x: math.sqrt(float(np.mean(x ** 2)))),
        "settling_time_s": _all_or_none(ts, np.max),
        "n_unsettled": int(np.isnan(ts).sum()),
        "a_lat_peak_mps2": _max(_col(members, "a_lat_peak_mps2")),
        "jerk_lat_rms_mps3": _max(_col(members, "jerk_lat_rms_mps3")),
        "jerk_lon_rms_mps3": _max(_col(members, "jerk_lon_rms_mps3")),
        "t_lat_above_comfort_s": _max(above) if np.isfinite(_col(members, "t_lat_medium_s")).any() else None,
        "t_lon_above_comfort_s": _max(_col(members, "t_lon_above_comfort_s")),
        "slip_over_s": _max(_col(members, "slip_over_s")),
        "traction_over_s": _max(_col(members, "traction_over_s")),
        "friction_over_s": _max(_col(members, "friction_over_s")),
        "collisions": None, "min_ttc_s": None, "emergency_brakes": None,
        "requested_veh": None, "inserted_veh": None, "flow_measured_veh_h": None,
        "density_measured_veh_km": None,
        **_energy_metrics(members),
        "leader_age_mean_s": _max(_col(members, "leader_age_mean_s")),
        "leader_age_p95_s": _max(_col(members, "leader_age_p95_s")),
        "comm_timeouts": None,
        "min_gap_m": float(min(gaps)) if gaps else None,
        "law_fallbacks": int((meta.get("event_counts") or {}).get("law_fallback", 0)),
        **_incidents(meta),
    }
    if (meta.get("scenario") or {}).get("road") is not None:
        from analysis.runs.section_measures import section_measures  # pandas, SUMO runs only

        out.update(_sumo_metrics(run_dir, set(map(str, members.index)), meta))
        out.update(section_measures(run_dir, meta))
    return out


def traffic_only_values(run_dir: Path, meta: dict) -> dict[str, Any]:
    """The metrics of a road run no formation entered (a penetration study's 0 %): the
    traffic's (SUMO's counts, the section measures) and the incidents; the members' None.

    Parameters
    ----------
    run_dir : Path
        Run directory (its SUMO and section tables).
    meta : dict
        ``run.json`` content.

    Returns
    -------
    dict
        Metric name -> float, int or None.
    """
    from analysis.runs.section_measures import section_measures

    return {**_sumo_metrics(run_dir, set(), meta), **section_measures(run_dir, meta), **_incidents(meta)}


def _incidents(meta: dict) -> dict[str, Any]:
    """run.json ``incidents`` (sim/incidents.py; None for a run recorded without them) and
    the formation flows' shortfall (``formation_shortfall``: None without formation flows)."""
    inc = meta.get("incidents") or {}
    out: dict[str, Any] = {k: (int(inc[k]) if k in inc else None)
                           for k in ("member_collisions", "member_removed", "stranded", "sumo_collision_artefacts")}
    flows = meta.get("formation_flows") or {}
    due = sum(int(c.get("requested") or 0) for c in flows.values())
    out["formation_shortfall"] = (1.0 - sum(int(c.get("inserted") or 0) for c in flows.values()) / due
                                  if due else (0.0 if flows else None))
    return {**out, **merge_values(meta)}


def merge_values(meta: dict) -> dict[str, Any]:
    """The ramp vehicles' columns of a case's row.

    Parameters
    ----------
    meta : dict
        ``run.json`` content (its ``merges``: sumo/merge_watch.py).

    Returns
    -------
    dict
        ``ramp_vehicles`` (over the formations), ``ramp_merged_before_lane_end``,
        ``ramp_speed_loss_mps`` and ``ramp_wait_s`` (means weighted by each formation's count);
        all None without on-ramps or ramp vehicles.
    """
    seen = [m for m in ((meta.get("merges") or {}).get("by_formation") or {}).values() if m.get("ramp_vehicles")]
    n = sum(int(m["ramp_vehicles"]) for m in seen)
    if not n:
        return dict.fromkeys(("ramp_vehicles", "ramp_merged_before_lane_end", "ramp_speed_loss_mps", "ramp_wait_s"))
    mean = (lambda k: sum(float(m[k]) * int(m["ramp_vehicles"]) for m in seen) / n)  # noqa: E731
    return {"ramp_vehicles": n, "ramp_merged_before_lane_end": sum(int(m["merged_before_lane_end"]) for m in seen),
            "ramp_speed_loss_mps": mean("ramp_speed_loss_mps"), "ramp_wait_s": mean("ramp_wait_s")}


def summary_frame(rows: list[dict], swept: dict[str, str]) -> pd.DataFrame:
    """Rows (any order) -> the summary table sorted by case index, with fixed dtypes.

    Parameters
    ----------
    rows : list of dict
        Case rows (:func:`empty_row` layout).
    swept : dict
        Swept dotted path -> pandas dtype of its column (``"json"``: values as JSON text).

    Returns
    -------
    DataFrame
        Columns :data:`ID_COLUMNS`, the swept paths, :data:`STATUS_COLUMNS`,
        :data:`METRICS`, :data:`WALL_COLUMNS`.
    """
    import json

    cols = [*ID_COLUMNS, *swept, *STATUS_COLUMNS, *METRICS, *WALL_COLUMNS]
    df = pd.DataFrame(sorted(rows, key=lambda r: r["case_index"]), columns=cols)
    dtypes = {"case_id": "string", "case_index": "int64", "seed": "int64", "status": "string",
              "reason": "string", "t_end_s": "float64",
              "twin_status": "string", "twin_reason": "string", "wall_s": "float64", "host": "string",
              "pid": "Int64"}
    dtypes.update({k: ("Int64" if k in COUNT_METRICS else "float64") for k in METRICS})
    for k, t in swept.items():
        if t == "json":
            df[k] = df[k].map(lambda v: json.dumps(v, sort_keys=True))
            t = "string"
        dtypes[k] = t
    return df.astype(dtypes).reset_index(drop=True)


def swept_dtypes(cases: list[dict], keys: list[str]) -> dict[str, str]:
    """Column dtype of each swept path over every case.

    Parameters
    ----------
    cases : list of dict
        ``Case.model_dump(mode="json")`` of every case.
    keys : list of str
        Swept dotted paths.

    Returns
    -------
    dict
        Path -> ``"boolean"``, ``"int64"``, ``"float64"``, ``"string"`` or ``"json"`` (tables,
        lists or mixed types, stored as JSON text).
    """
    out = {}
    for k in keys:
        vals = [c["values"][k] for c in cases]
        if all(isinstance(v, bool) for v in vals):
            out[k] = "boolean"
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
            out[k] = "int64"
        elif all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
            out[k] = "float64"
        elif all(isinstance(v, str) for v in vals):
            out[k] = "string"
        else:
            out[k] = "json"
    return out
