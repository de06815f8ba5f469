"""Per-run traffic computation: from a loaded run (and its baseline twin) to tables.

Chooses the rows and vehicles, builds the member-vs-vehicle pairs of each time step and
handles missing tables; the measures themselves are the pure functions of
:mod:`analysis.metrics.traffic`. No file is written here. Definitions: ``docs/metrics.md``,
section "Traffic interaction".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import Issue, RunData
from analysis.metrics import traffic as tr
from analysis.metrics.conflicts import time_keys
from analysis.runs.baseline_run import BaselineData, baseline_section, load_baseline, twin_section
from analysis.runs.conflict_run import (CONFLICT_MEMBER_METRICS, CONFLICT_RUN_METRICS,
                                        SSM_RUN_METRICS, recorded_section, ssm_section)
from analysis.runs.interaction_run import (PAIR_CHUNK, background_rows, member_interaction,
                                           member_rows)
from analysis.runs.near_formation import background_near
from analysis.runs.settings import AnalysisSettings
from analysis.runs.twin_sections import TWIN_METRICS

__all__ = [
    "TRAFFIC_MEMBER_METRICS",
    "TRAFFIC_RUN_METRICS",
    "TRAFFIC_COMPARE_METRICS",
    "PAIR_CHUNK",
    "BaselineData",
    "TrafficAnalysis",
    "load_baseline",
    "time_keys",
    "member_rows",
    "compute_traffic",
]

TRAFFIC_MEMBER_METRICS: dict[str, str] = {
    "clearance_min_m": "m", "clearance_min_with": "-", "clearance_min_t_s": "s",
    "t_clearance_below_s": "s", "clearance_members_min_m": "m", "clearance_bg_min_m": "m",
    "lat_gap_min_m": "m", "t_lat_gap_below_s": "s",
    "ttc2d_min_s": "s", "ttc2d_min_with": "-", "ttc2d_min_t_s": "s", "t_ttc2d_below_s": "s",
    "headway_min_s": "s", "headway_mean_s": "s", "t_headway_below_s": "s",
    "follower_headway_min_s": "s", "t_follower_headway_below_s": "s",
    "ssm_n_conflicts": "-", "ssm_ttc_min_s": "s", "ssm_drac_max_mps2": "m/s^2",
    **CONFLICT_MEMBER_METRICS,
    "n_cut_ins": "-", "n_lane_changes": "-", "n_collisions": "-", "n_teleports": "-",
}
"""Per-member traffic metrics with their units (columns of ``metrics.csv`` too)."""

TRAFFIC_RUN_METRICS: dict[str, str] = {
    "member_footprint": "-",
    **SSM_RUN_METRICS, **CONFLICT_RUN_METRICS,
    "clearance_min_m": "m", "clearance_members_min_m": "m", "clearance_bg_min_m": "m",
    "lat_gap_min_m": "m", "ttc2d_min_s": "s", "headway_min_s": "s", "follower_headway_min_s": "s",
    "t_clearance_below_s": "s", "t_lat_gap_below_s": "s", "t_ttc2d_below_s": "s",
    "t_headway_below_s": "s", "t_follower_headway_below_s": "s", "n_pairs": "-",
    "bg_n_vehicles": "-", "bg_n_vehicles_near": "-", "bg_speed_mean_near_mps": "m/s",
    "bg_speed_mean_behind_mps": "m/s", "bg_speed_mean_alongside_mps": "m/s",
    "bg_speed_mean_ahead_mps": "m/s", "bg_speed_mean_by_lane_mps": "m/s",
    "bg_time_loss_total_s": "s", "bg_time_loss_mean_s": "s",
    "n_lane_changes_members": "-", "n_lane_changes_bg": "-", "n_lane_changes_bg_near": "-",
    "n_cut_ins": "-", "n_collisions": "-", "n_collisions_member": "-", "n_teleports": "-",
    "n_teleports_member": "-",
    "baseline_run_dir": "-", "baseline_section_m": "m", "baseline_n_common": "-",
    "baseline_n_compared": "-", "baseline_n_full_section": "-",
    "baseline_tt_run_mean_s": "s", "baseline_tt_base_mean_s": "s",
    "baseline_delta_mean_s": "s", "baseline_delta_max_s": "s", "baseline_delta_total_s": "s",
    "baseline_v_run_mps": "m/s", "baseline_v_base_mps": "m/s",
    "baseline_bg_speed_mean_near_mps": "m/s", "baseline_bg_speed_delta_near_mps": "m/s",
    **TWIN_METRICS,
}
"""Run-level traffic metrics with their units (``metrics.json`` ``traffic.run``)."""

TRAFFIC_COMPARE_METRICS: tuple[str, ...] = (
    "ssm_n_member", "ssm_ttc_min_member_s", "ssm_drac_max_member_mps2", "ssm_n_other",
    "clearance_min_m", "clearance_members_min_m", "clearance_bg_min_m", "lat_gap_min_m",
    "ttc2d_min_s", "t_ttc2d_below_s", "headway_min_s", "follower_headway_min_s", "bg_speed_mean_near_mps",
    "bg_time_loss_total_s", "n_cut_ins", "n_lane_changes_bg_near", "n_collisions",
    "n_teleports", "baseline_delta_mean_s", "baseline_delta_total_s")
"""Traffic rows of the ``compare_runs`` table."""

_BG_GEOMETRY = ("t", "vehicle_id", "x", "y", "heading", "v", "length", "width")

@dataclass(frozen=True)
class TrafficAnalysis:
    """Traffic metrics of one run (no files written)."""

    run: dict[str, Any]  # TRAFFIC_RUN_METRICS
    members: pd.DataFrame  # index "id", columns TRAFFIC_MEMBER_METRICS
    ssm: pd.DataFrame  # analysis.metrics.traffic.ssm_summary by group "member"/"other"
    member_conflicts: pd.DataFrame  # SSM conflicts involving a member, merged, artefacts left out
    ssm_extremes: pd.DataFrame  # SSM records with TTC 0 or an extreme DRAC, with their "class"
    # conflicts from the recording (analysis.metrics.conflicts.CONFLICT_COLUMNS)
    conflicts: pd.DataFrame
    baseline: pd.DataFrame | None  # per-vehicle comparison with the twin, or None
    twin: pd.DataFrame | None  # per-vehicle comparison at the sections (twin.csv), or None
    series: pd.DataFrame  # per member sample: t, vehicle_id, clearance_m (to any vehicle),
    # clearance_members_m, clearance_bg_m, ttc2d_s, lat_gap_m, headway_s, follower_headway_s
    unavailable: dict[str, str]  # metric group -> why not computed
    issues: tuple[Issue, ...]


def compute_traffic(data: RunData, settings: AnalysisSettings,
                    baseline: BaselineData | None = None) -> TrafficAnalysis:
    """Compute every traffic metric of a loaded run.

    Parameters
    ----------
    data : RunData
        Output of :func:`analysis.load.run_data.load_run`.
    settings : AnalysisSettings
        Thresholds, interaction range, TTC horizon (see :mod:`analysis.runs.summary`).
    baseline : BaselineData, optional
        The twin run without the formation (:func:`load_baseline`); adds the
        ``baseline_*`` metrics and the per-vehicle comparison.

    Returns
    -------
    TrafficAnalysis
        Run-level and per-member metrics, SSM summary, member conflicts, baseline
        comparison, per-sample series, reasons for what is missing, and issues.
    """
    st, dt, meta = settings, data.dt, data.meta
    issues: list[Issue] = []
    unavailable: dict[str, str] = {}
    ids = [m.id for m in data.members]
    id_set = set(ids)
    run: dict[str, Any] = {k: None for k in TRAFFIC_RUN_METRICS}
    mem = pd.DataFrame(index=pd.Index(ids, name="id"), columns=list(TRAFFIC_MEMBER_METRICS),
                       dtype=object)
    fp, fp_source = tr.member_footprint(meta.get("scenario"), meta.get("members"))
    run["member_footprint"] = (f"{fp.length:g} x {fp.width:g} m, CoG to front bumper "
                               f"{fp.cog_to_front:g} m ({fp_source})")
    if "assumed" in fp_source:
        issues.append(Issue("warning", "assumed_footprint", "scenario.vehicle", fp_source))
    bg, ev = data.tables.get("background"), data.tables.get("events")

    # --- 2-D interaction between members and every vehicle near them -------------------
    M = member_rows(data, tr.member_footprints(meta.get("scenario"), meta.get("members")) or fp, dt)
    road = bool(len(M)) and np.isfinite(M[["s", "d"]].to_numpy(float)).any()
    bg_ok = bg is not None and all(c in bg.columns for c in _BG_GEOMETRY)
    if bg is None:
        unavailable["background"] = "background.parquet missing: only member-member pairs"
    elif not bg_ok:
        miss = [c for c in _BG_GEOMETRY if c not in bg.columns]
        unavailable["background"] = f"background.parquet lacks {', '.join(miss)}"
    B = background_rows(bg, dt, id_set) if bg_ok else M.iloc[:0]
    road_bg = road and bg_ok and "s" in bg.columns and "d" in bg.columns
    if not road:
        unavailable["lateral gap / headway"] = ("no road coordinates s, d in the "
                                                "trajectories (not a road run)")
    P = pd.concat([B, M], ignore_index=True) if len(B) else M
    series, missing = member_interaction(M, P, ids, st, dt, road, mem, run)
    if missing:
        unavailable["interaction"] = missing
    win, near = background_near(bg, bg_ok, road, road_bg, M, id_set, st, dt, run)
    if ev is None or not {"kind", "vehicle_id"} <= set(ev.columns):
        unavailable["events"] = ("events.parquet missing" if ev is None
                                 else "events.parquet lacks kind / vehicle_id")
    else:
        _event_metrics(ev, ids, near, road_bg, dt, run, mem)
        verdict = (meta.get("incidents") or {}).get("member_collisions")
        if verdict is not None:  # the run's verdict (sim/incidents.py): the same count everywhere
            run["n_collisions_member"] = int(verdict)

    sr, conf_tab = _conflicts(data, M, B, bg_ok, road, st, run, mem, unavailable)
    base_tab = twin_tab = None
    if baseline is not None:
        base_tab = baseline_section(baseline, data, M, bg_ok, road, win, st, run, issues,
                                    unavailable)
        twin_tab = twin_section(baseline, data, st, run, issues, unavailable)
    for c in ("ssm_n_conflicts", "conflict_n", "n_cut_ins", "n_lane_changes", "n_collisions",
              "n_teleports"):
        mem[c] = [None if v is None or (isinstance(v, float) and math.isnan(v)) else int(v)
                  for v in mem[c]]
    return TrafficAnalysis(run=run, members=mem, ssm=sr.table, member_conflicts=sr.member_conflicts,
                           ssm_extremes=sr.extremes, conflicts=conf_tab, baseline=base_tab, twin=twin_tab, series=series, unavailable=unavailable,
                           issues=tuple(issues))


def collision_contacts(e: pd.DataFrame, dt: float) -> pd.DataFrame:
    """``events`` with its ``collision`` rows reduced to one per contact: SUMO reports a pair
    at every step it touches; a pair (either order) reported again within 1.5 record steps
    ``dt`` [s] of its last report is the same contact (as the run's verdict counts them,
    sim/incidents.py)."""
    col = e["kind"] == "collision"
    if not col.any() or "t" not in e.columns:
        return e
    c = e.loc[col].assign(_pair=[tuple(sorted(p)) for p in zip(e.loc[col, "vehicle_id"],
                                                                 e.loc[col, "other_id"])])
    c = c.sort_values("t", kind="stable")
    t = pd.to_numeric(c["t"], errors="coerce")
    prev = t.groupby(c["_pair"]).shift()
    first = prev.isna() | (t - prev > 1.5 * dt)
    return pd.concat([e.loc[~col], c.loc[first].drop(columns="_pair")]).sort_index(kind="stable")


def _event_metrics(ev: pd.DataFrame, ids: list[str], near: pd.DataFrame, road_bg: bool,
                   dt: float, run: dict[str, Any], mem: pd.DataFrame) -> None:
    """Collisions, teleports, cut-ins and lane changes from ``events.parquet`` (filled into
    ``run`` and the members' table ``mem``)."""
    id_set = set(ids)
    e = ev.copy()
    for c in ("kind", "vehicle_id", "other_id"):
        e[c] = e[c].astype(str) if c in e.columns else ""
    e = collision_contacts(e, dt)
    kind = e["kind"]
    involved = e["vehicle_id"].isin(id_set) | e["other_id"].isin(id_set)
    run["n_collisions"] = int((kind == "collision").sum())
    run["n_collisions_member"] = int(((kind == "collision") & involved).sum())
    run["n_teleports"] = int((kind == "teleport").sum())
    run["n_teleports_member"] = int(((kind == "teleport")
                                     & e["vehicle_id"].isin(id_set)).sum())
    run["n_cut_ins"] = int(((kind == "cut_in") & e["other_id"].isin(id_set)).sum())
    lc = e.loc[kind == "lane_change"]
    run["n_lane_changes_members"] = int(lc["vehicle_id"].isin(id_set).sum())
    lc_bg = lc.loc[~lc["vehicle_id"].isin(id_set)]
    run["n_lane_changes_bg"] = int(len(lc_bg))
    if road_bg and len(lc_bg):
        k = pd.DataFrame({"vehicle_id": lc_bg["vehicle_id"].to_numpy(),
                          "key": time_keys(pd.to_numeric(lc_bg["t"], errors="coerce"),
                                           dt)})
        nk = near.assign(vehicle_id=near["vehicle_id"].astype(str))[
            ["vehicle_id", "key"]].drop_duplicates() if len(near) else \
            pd.DataFrame(columns=["vehicle_id", "key"])
        run["n_lane_changes_bg_near"] = int(len(k.merge(nk, on=["vehicle_id", "key"])))
    elif road_bg:
        run["n_lane_changes_bg_near"] = 0
    counts = pd.concat([
        tr.event_counts(e, ids, ["collision"]),
        tr.event_counts(e, ids, ["teleport", "lane_change"], roles=("vehicle_id",)),
        tr.event_counts(e, ids, ["cut_in"], roles=("other_id",))], axis=1)
    for src, dst in (("collision", "n_collisions"), ("teleport", "n_teleports"),
                     ("lane_change", "n_lane_changes"), ("cut_in", "n_cut_ins")):
        mem[dst] = counts[src].astype(object)


def _conflicts(data: RunData, M: pd.DataFrame, B: pd.DataFrame, bg_ok: bool, road: bool,
               st: AnalysisSettings, run: dict[str, Any], mem: pd.DataFrame,
               unavailable: dict[str, str]) -> tuple[Any, pd.DataFrame]:
    """SSM conflicts (SUMO's device) and conflicts from the recording, filled into ``run``
    and ``mem``; returns the SSM section and the recorded conflicts table."""
    ids, dt, ev = [m.id for m in data.members], data.dt, data.tables.get("events")
    t_first = float(data.trajectories["t"].min())
    t_last = float(data.trajectories["t"].max())
    bg_keys = set(zip(B["vehicle_id"], B["key"])) if bg_ok else None
    member_s = M[["t", "vehicle_id", "s"]] if len(M) else None
    sr = ssm_section(data.tables.get("ssm"), ids, t_first, t_last, st, bg_keys, dt, ev,
                     member_s)
    run.update(sr.run)
    if sr.unavailable:
        unavailable["ssm"] = sr.unavailable
    for m_id, vals in sr.members.items():
        for k, v in vals.items():
            mem.loc[m_id, k] = v
    conf_tab = pd.DataFrame(columns=["follower", "leader"])
    if road and len(M):
        c_run, c_mem, conf_tab = recorded_section(pd.concat([M, B], ignore_index=True) if len(B) else M,
                                                  ids, st)
        run.update(c_run)
        for m_id, vals in c_mem.items():
            for k, v in vals.items():
                mem.loc[m_id, k] = v
    else:
        unavailable["conflicts"] = "no road coordinates or lanes in the trajectories (not a road run)"
    return sr, conf_tab
