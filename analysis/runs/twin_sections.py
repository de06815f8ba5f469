"""The formation run against its twin at the measurement sections (docs/metrics.md,
"Against the twin at the sections"): the vehicles matched by id, the population timed over
the whole stretch in both runs, and every measure over a named population.

Reads ``sections.parquet``, ``departures.parquet`` and ``events.parquet`` of both runs (written
by formation_traci/sumo/sections.py); pure functions of those tables, no file written here.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import read_table

__all__ = ["SectionTables", "read_sections", "twin_comparison", "TWIN_METRICS", "EFFECTS"]

TWIN_METRICS: dict[str, str] = {
    "stretch_m": "m", "stretch_population": "-", "matched_share": "-", "stretch_coverage": "-",
    "twin_n_timed": "-", "twin_cleared_both": "-", "twin_departures_same": "-", "twin_departures_moved": "-",
    "twin_depart_delay_total_s": "s",
    "twin_tt_run_mean_s": "s", "twin_tt_twin_mean_s": "s", "twin_delay_mean_s": "s",
    "twin_delay_total_s": "s", "twin_exit_delay_total_s": "s",
    "twin_speed_run_mps": "m/s", "twin_speed_twin_mps": "m/s", "twin_speed_delta_mps": "m/s",
    "twin_spot_speed_delta_mps": "m/s", "twin_spot_speed_var_delta_m2ps2": "m^2/s^2",
    "twin_throughput_run_veh_h": "veh/h", "twin_throughput_twin_veh_h": "veh/h",
    "twin_throughput_delta_veh_h": "veh/h",
    "twin_lane_changes_run": "-", "twin_lane_changes_twin": "-", "twin_lane_changes_delta": "-",
    "twin_conflicts_run": "-", "twin_conflicts_twin": "-", "twin_conflicts_delta": "-",
}
"""Run-level keys of the twin comparison (``traffic.run`` of metrics.json) and their units."""

EFFECTS: dict[str, str] = {
    "delay_mean_s": "twin_delay_mean_s", "delay_total_s": "twin_delay_total_s",
    "exit_delay_total_s": "twin_exit_delay_total_s", "speed_mps": "twin_speed_delta_mps",
    "spot_speed_mps": "twin_spot_speed_delta_mps", "spot_speed_var_m2ps2": "twin_spot_speed_var_delta_m2ps2",
    "throughput_veh_h": "twin_throughput_delta_veh_h", "lane_changes": "twin_lane_changes_delta",
    "conflicts": "twin_conflicts_delta",
}
"""Paired effects (formation run minus twin): effect name -> its run-level key."""

POPULATIONS: dict[str, str] = {
    "stretch": "background vehicles that were in the stretch while the formation ran (first section "
               "passed before its end, last section not before its start, in either run), less those "
               "cleared at the formation's insertion in both runs (twin_cleared_both)",
    "timed": "the stretch population timed from the same first section to the last section in both "
             "runs (delay, travel time, stretch speed, spot speeds, lane changes, conflicts)",
    "downstream": "every background vehicle passing the last (downstream) section during the "
                  "formation's run [0, t_end], each run counted on its own",
}
"""The populations the measures are over (metrics.json ``traffic.twin_populations``)."""


class SectionTables:
    """One run's section tables: passages, departures, events and the stretch's end time."""

    def __init__(self, passages, departures, events, t_end: float):
        self.passages, self.departures, self.events, self.t_end = passages, departures, events, t_end


def read_sections(run_dir: str | Path, meta: dict) -> SectionTables | None:
    """The section tables of a run.

    Parameters
    ----------
    run_dir : str or Path
        Run directory (``sections.parquet``, ``departures.parquet``, ``events.parquet``).
    meta : dict
        Its run.json (``sections``: whether they were on, the formation's end ``t_end``).

    Returns
    -------
    SectionTables or None
        None when the run has none (sections off, a run of an older version).
    """
    d = Path(run_dir)
    p, _ = read_table(d / "sections.parquet")
    dep, _ = read_table(d / "departures.parquet")
    ev, _ = read_table(d / "events.parquet")
    sec = meta.get("sections") or {}
    if p is None or dep is None or not sec.get("enabled"):
        return None
    return SectionTables(p, dep, ev, float(sec.get("t_end", meta.get("t_end") or 0.0)))


def _ids_of(ev: pd.DataFrame | None, kind: str, col: str = "vehicle_id") -> set[str]:
    if ev is None or not len(ev):
        return set()
    return set(ev.loc[ev["kind"] == kind, col].astype(str))


def _vehicle_table(p: pd.DataFrame, last: int) -> pd.DataFrame:
    """Per background vehicle: entry section and time, exit time at the last section, lane
    changes between them."""
    bg = p[~p["member"].astype(bool)].sort_values(["vehicle_id", "t"], kind="stable")
    g = bg.groupby("vehicle_id", sort=True)
    first = g.first()
    out = pd.DataFrame({"entry": first["section"].astype(int), "s_entry": first["s_m"], "t_entry": first["t"]})
    ex = bg[bg["section"] == last].groupby("vehicle_id")["t"].first()
    out["t_exit"] = ex.reindex(out.index)
    inner = bg[bg["t"] > g["t"].transform("first")]  # (a map of no rows would compare t with text)
    out["lane_changes"] = inner.groupby("vehicle_id")["lane_changes_before"].sum().reindex(out.index).fillna(0)
    return out


def _reasons(vid: str, side: str, other: SectionTables, this: SectionTables) -> str:
    """Why a vehicle seen at the sections in ``this`` run has no passage in ``other``."""
    dep = other.departures
    if vid in _ids_of(other.events, "cleared_at_insertion"):
        return f"cleared at the formation's insertion in the {side}"
    if vid in _ids_of(other.events, "handover", "other_id"):
        return f"taken over by a join in the {side}"
    if vid not in set(dep["vehicle_id"].astype(str)):
        return f"never inserted in the {side}"
    if vid in _ids_of(other.events, "teleport") or vid in _ids_of(other.events, "collision"):
        return f"teleported or collided in the {side}"
    return f"passed no section in the {side} before its end"


def _conflicts(p: pd.DataFrame, ttc_s: float) -> pd.Series:
    """Per passage: True when the vehicle came up on the previous vehicle over the same loop
    (section and lane) with a time to collision below ``ttc_s`` [s]: the gap
    ``v_lead * (t - t_lead) - length_lead`` closed at ``v - v_lead`` > 0."""
    q = p.sort_values(["section", "lane", "t"], kind="stable")
    same = (q["section"].eq(q["section"].shift())) & (q["lane"].eq(q["lane"].shift()))
    v_l, t_l, len_l = q["v"].shift(), q["t"].shift(), q["length"].shift()
    gap = v_l * (q["t"] - t_l) - len_l
    closing = q["v"] - v_l
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(same & (closing > 0), gap / closing, np.inf)
    return pd.Series(ttc < ttc_s, index=q.index).reindex(p.index)


def _throughput(p: pd.DataFrame, last: int, t_end: float) -> float | None:
    if not t_end > 0:
        return None
    x = p[(p["section"] == last) & ~p["member"].astype(bool) & (p["t"] >= 0) & (p["t"] <= t_end)]
    return float(x["vehicle_id"].nunique() * 3600.0 / t_end)


def twin_comparison(run: SectionTables, twin: SectionTables, sections: list[dict],
                    ttc_s: float = 3.0) -> tuple[dict[str, Any], pd.DataFrame, dict[str, Any]]:
    """The formation run against its twin at the sections.

    Parameters
    ----------
    run : SectionTables
        The formation run's tables (:func:`read_sections`).
    twin : SectionTables
        Its twin's.
    sections : list of dict
        run.json ``sections.sections``: index, role, ``s_m`` of each, upstream first.
    ttc_s : float
        Time to collision [s] below which a section passage is a conflict.

    Returns
    -------
    (metrics, vehicles, detail)
        ``metrics``: the :data:`TWIN_METRICS` values; ``vehicles``: one row per vehicle of
        the population (``matched``, ``timed``, ``reason`` when not, travel times and delays);
        ``detail``: reasons counted, departures compared, per-section spot speeds.
    """
    last = int(sections[-1]["section"])
    s_of = {int(s["section"]): float(s["s_m"]) for s in sections}
    t_end = min(run.t_end, twin.t_end)
    a, b = _vehicle_table(run.passages, last), _vehicle_table(twin.passages, last)

    def in_window(x):
        return (x["t_entry"] < t_end) & ~(x["t_exit"] < 0)

    cleared = _ids_of(run.events, "cleared_at_insertion") & _ids_of(twin.events, "cleared_at_insertion")
    pop = sorted((set(a.index[in_window(a)]) | set(b.index[in_window(b)])) - cleared)
    v = pd.DataFrame(index=pd.Index(pop, name="vehicle_id"))
    v = v.join(a.add_suffix("_run")).join(b.add_suffix("_twin"))
    v["matched"] = v["entry_run"].notna() & v["entry_twin"].notna()
    v["timed"] = v["matched"] & (v["entry_run"] == v["entry_twin"]) & v["t_exit_run"].notna() \
        & v["t_exit_twin"].notna()
    v["reason"] = _why_not(v, run, twin)
    T = v[v["timed"]].copy()
    T["length_m"] = s_of[last] - T["entry_run"].map(s_of)
    T["tt_run_s"] = T["t_exit_run"] - T["t_entry_run"]
    T["tt_twin_s"] = T["t_exit_twin"] - T["t_entry_twin"]
    T["delay_s"] = T["tt_run_s"] - T["tt_twin_s"]
    T["exit_delay_s"] = T["t_exit_run"] - T["t_exit_twin"]
    v = v.join(T[["length_m", "tt_run_s", "tt_twin_s", "delay_s", "exit_delay_s"]])
    n = len(v)
    m: dict[str, Any] = {k: None for k in TWIN_METRICS}
    m.update(stretch_m=[s_of[int(sections[0]["section"])], s_of[last]], stretch_population=n,
             twin_cleared_both=len(cleared),
             matched_share=float(v["matched"].mean()) if n else None,
             stretch_coverage=float(v["timed"].mean()) if n else None, twin_n_timed=int(len(T)))
    detail = {"unmatched_reasons": v.loc[~v["matched"], "reason"].value_counts().to_dict(),
              "untimed_reasons": v.loc[v["matched"] & ~v["timed"], "reason"].value_counts().to_dict(),
              "departures": _departures(run, twin, m)}
    if len(T):
        m.update(twin_tt_run_mean_s=float(T["tt_run_s"].mean()), twin_tt_twin_mean_s=float(T["tt_twin_s"].mean()),
                 twin_delay_mean_s=float(T["delay_s"].mean()), twin_delay_total_s=float(T["delay_s"].sum()),
                 twin_exit_delay_total_s=float(T["exit_delay_s"].sum()),
                 twin_speed_run_mps=float(T["length_m"].sum() / T["tt_run_s"].sum()),
                 twin_speed_twin_mps=float(T["length_m"].sum() / T["tt_twin_s"].sum()))
        m["twin_speed_delta_mps"] = m["twin_speed_run_mps"] - m["twin_speed_twin_mps"]
        m.update(_spot_and_events(run, twin, T, ttc_s, detail, sections))
    for side, tab in (("run", run), ("twin", twin)):
        m[f"twin_throughput_{side}_veh_h"] = _throughput(tab.passages, last, t_end)
    if m["twin_throughput_run_veh_h"] is not None and m["twin_throughput_twin_veh_h"] is not None:
        m["twin_throughput_delta_veh_h"] = m["twin_throughput_run_veh_h"] - m["twin_throughput_twin_veh_h"]
    return m, v.reset_index(), detail


def _why_not(v: pd.DataFrame, run: SectionTables, twin: SectionTables) -> pd.Series:
    """Per vehicle of the population: why it is not matched or not timed ("" when it is)."""
    reason = pd.Series("", index=v.index, dtype=object)
    for vid in v.index[~v["matched"]]:
        reason[vid] = (_reasons(vid, "twin", twin, run) if pd.isna(v.at[vid, "entry_twin"])
                       else _reasons(vid, "formation run", run, twin))
    for vid in v.index[v["matched"] & ~v["timed"]]:
        if v.at[vid, "entry_run"] != v.at[vid, "entry_twin"]:
            reason[vid] = "entered the stretch at different sections"
        else:
            side = "formation run" if pd.isna(v.at[vid, "t_exit_run"]) else "twin"
            reason[vid] = f"did not reach the last section in the {side} (drain ended)"
    return reason


def _departures(run: SectionTables, twin: SectionTables, m: dict[str, Any]) -> dict[str, int]:
    """The two runs' insertions compared by id: fills the ``twin_departures_*`` metrics of
    ``m``; returns the counts of ``twin_detail.departures``."""
    dep = run.departures.merge(twin.departures, on="vehicle_id", how="outer", suffixes=("_run", "_twin"))
    both = dep.dropna()
    later = both["depart_run"] - both["depart_twin"]
    m.update(twin_departures_same=int((later == 0).sum()), twin_departures_moved=int((later != 0).sum()),
             twin_depart_delay_total_s=float(later.sum()))
    return {"run": int(dep["depart_run"].notna().sum()), "twin": int(dep["depart_twin"].notna().sum()),
            "only_run": int(dep["depart_twin"].isna().sum()), "only_twin": int(dep["depart_run"].isna().sum()),
            "same_time": m["twin_departures_same"], "later_in_run": int((later > 0).sum()),
            "earlier_in_run": int((later < 0).sum())}


def _spot_and_events(run, twin, T, ttc_s, detail, sections) -> dict[str, Any]:
    """Spot speeds, lane changes and conflicts of the timed vehicles, both runs."""
    ids = set(T.index)
    out: dict[str, Any] = {}
    per_sec, spots = [], {}
    for side, tab in (("run", run), ("twin", twin)):
        p = tab.passages
        conf = _conflicts(p, ttc_s)
        mine = p["vehicle_id"].astype(str).isin(ids) & ~p["member"].astype(bool)
        spots[side] = p[mine]
        out[f"twin_conflicts_{side}"] = int(conf[mine].sum())
        out[f"twin_lane_changes_{side}"] = int(T[f"lane_changes_{side}"].sum())
    out["twin_conflicts_delta"] = out["twin_conflicts_run"] - out["twin_conflicts_twin"]
    out["twin_lane_changes_delta"] = out["twin_lane_changes_run"] - out["twin_lane_changes_twin"]
    r, t = spots["run"]["v"].to_numpy(float), spots["twin"]["v"].to_numpy(float)
    if r.size and t.size:
        out["twin_spot_speed_delta_mps"] = float(r.mean() - t.mean())
        out["twin_spot_speed_var_delta_m2ps2"] = float(r.var() - t.var())
    for sec in sections:
        k = int(sec["section"])
        rs = spots["run"].loc[spots["run"]["section"] == k, "v"]
        ts = spots["twin"].loc[spots["twin"]["section"] == k, "v"]
        per_sec.append({"section": k, "role": sec["role"], "s_m": sec["s_m"], "n_run": int(len(rs)),
                        "n_twin": int(len(ts)),
                        "v_run_mps": float(rs.mean()) if len(rs) else None,
                        "v_twin_mps": float(ts.mean()) if len(ts) else None,
                        "v_var_run_m2ps2": float(rs.var(ddof=0)) if len(rs) else None,
                        "v_var_twin_m2ps2": float(ts.var(ddof=0)) if len(ts) else None})
    detail["sections"] = per_sec
    return out
