"""Per-run traffic computation: from a loaded run (and its baseline twin) to tables.

Chooses the rows and vehicles, builds the member-vs-vehicle pairs of each time step and
handles missing tables; the measures themselves are the pure functions of
:mod:`analysis.traffic`. No file is written here. Definitions: ``docs/metrics.md``,
section "Traffic interaction".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis import traffic as tr
from analysis.conflict_run import (CONFLICT_MEMBER_METRICS, CONFLICT_RUN_METRICS, SSM_RUN_METRICS,
                                   recorded_section, ssm_section)
from analysis.conflicts import time_keys
from analysis.load import Issue, RunData, read_meta, read_table
from formation_traci.record.columns import VIRTUAL_CAR_ID

from analysis.settings import AnalysisSettings

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
}
"""Run-level traffic metrics with their units (``metrics.json`` ``traffic.run``)."""

TRAFFIC_COMPARE_METRICS: tuple[str, ...] = (
    "ssm_n_member", "ssm_ttc_min_member_s", "ssm_drac_max_member_mps2", "ssm_n_other",
    "clearance_min_m", "clearance_members_min_m", "clearance_bg_min_m", "lat_gap_min_m",
    "ttc2d_min_s", "t_ttc2d_below_s", "headway_min_s", "follower_headway_min_s", "bg_speed_mean_near_mps",
    "bg_time_loss_total_s", "n_cut_ins", "n_lane_changes_bg_near", "n_collisions",
    "n_teleports", "baseline_delta_mean_s", "baseline_delta_total_s")
"""Traffic rows of the ``compare_runs`` table."""

PAIR_CHUNK = 200_000
"""Vehicle pairs evaluated per vectorised batch (bounds memory on long runs) [-]."""

_BG_GEOMETRY = ("t", "vehicle_id", "x", "y", "heading", "v", "length", "width")


@dataclass(frozen=True)
class BaselineData:
    """What is read from a baseline twin run (``run --baseline``)."""

    run_dir: Path
    meta: dict[str, Any]
    background: pd.DataFrame | None
    issues: tuple[Issue, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class TrafficAnalysis:
    """Traffic metrics of one run (no files written)."""

    run: dict[str, Any]  # TRAFFIC_RUN_METRICS
    members: pd.DataFrame  # index "id", columns TRAFFIC_MEMBER_METRICS
    ssm: pd.DataFrame  # analysis.traffic.ssm_summary by group "member"/"other"
    member_conflicts: pd.DataFrame  # SSM conflicts involving a member, merged, artefacts left out
    ssm_extremes: pd.DataFrame  # SSM records with TTC 0 or an extreme DRAC, with their "class"
    conflicts: pd.DataFrame  # conflicts from the recording (analysis.conflicts.CONFLICT_COLUMNS)
    baseline: pd.DataFrame | None  # per-vehicle comparison with the twin, or None
    series: pd.DataFrame  # per member sample: t, vehicle_id, clearance_m (to any vehicle),
    # clearance_members_m, clearance_bg_m, ttc2d_s, lat_gap_m, headway_s, follower_headway_s
    unavailable: dict[str, str]  # metric group -> why not computed
    issues: tuple[Issue, ...]


def load_baseline(run_dir: str | Path) -> BaselineData:
    """Read the parts of a baseline twin run the comparison needs.

    Parameters
    ----------
    run_dir : str or Path
        Directory of the twin run (``run.json`` with ``"baseline": true``,
        ``background.parquet`` with every vehicle).

    Returns
    -------
    BaselineData
        Its metadata and background table (None when missing) and the problems met,
        named ``baseline:...``.
    """
    d = Path(run_dir)
    issues: list[Issue] = []
    if not d.is_dir():
        return BaselineData(d, {}, None, (Issue("error", "missing_baseline", str(d),
                                                "baseline run directory does not exist"),))
    meta, m_issues = read_meta(d)
    issues += [Issue(i.severity, i.kind, f"baseline:{i.what}", i.detail) for i in m_issues
               if i.kind in ("missing_file", "invalid_file", "run_status")]
    bg, b_issues = read_table(d / "background.parquet", "background.parquet")
    for i in b_issues:
        sev = "error" if i.kind == "missing_table" else i.severity
        issues.append(Issue(sev, i.kind, f"baseline:{i.what}", i.detail))
    if meta and meta.get("baseline") is not True:
        issues.append(Issue("warning", "baseline_mismatch", "baseline:run.json",
                            "run.json does not say \"baseline\": true; compared anyway"))
    return BaselineData(d, meta, bg, tuple(issues))


def member_rows(data: RunData, fp: tr.Footprint, dt: float) -> pd.DataFrame:
    """Members' rows as rectangles: body centre, velocity, road coordinates.

    Parameters
    ----------
    data : RunData
        The loaded run.
    fp : Footprint
        Members' body outline.
    dt : float
        Sample spacing [s] (for the time keys).

    Returns
    -------
    DataFrame
        One row per member sample with finite pose: ``t``, ``key``, ``vehicle_id``,
        ``x``, ``y`` (body centre [m]), ``heading`` [rad], ``v`` [m/s], ``vx``, ``vy``
        (velocity along heading + side slip [m/s]), ``length``, ``width`` [m], ``s``,
        ``d`` (body centre in road coordinates [m]; the CoG shift is resolved with the
        heading relative to the virtual car's), ``lane_index``, ``is_member`` (True).
    """
    traj = data.trajectories
    ids = [m.id for m in data.members]
    m = traj.loc[traj["vehicle_id"].isin(ids)]
    m = m.loc[np.isfinite(m[["x", "y", "heading"]].to_numpy(float)).all(axis=1)]
    t = m["t"].to_numpy(float)
    key = time_keys(t, dt)
    h = m["heading"].to_numpy(float)
    xc, yc = tr.body_centre(m["x"], m["y"], h, fp.cog_to_front, fp.length)
    v = np.nan_to_num(m["v"].to_numpy(float))
    beta = np.nan_to_num(m["beta"].to_numpy(float))
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "heading"]]
    vc_head = pd.Series(vc["heading"].to_numpy(float), index=time_keys(vc["t"], dt))
    vc_head = vc_head[~vc_head.index.duplicated()]
    rel = h - np.nan_to_num(vc_head.reindex(key).to_numpy(float), nan=0.0) if len(vc) \
        else np.zeros_like(h)
    off = fp.cog_to_front - 0.5 * fp.length
    return pd.DataFrame({
        "t": t, "key": key, "vehicle_id": m["vehicle_id"].to_numpy(str), "x": xc, "y": yc,
        "heading": h, "v": v, "vx": v * np.cos(h + beta), "vy": v * np.sin(h + beta),
        "length": fp.length, "width": fp.width,
        "s": m["s"].to_numpy(float) + off * np.cos(rel),
        "d": m["d"].to_numpy(float) + off * np.sin(rel),
        "lane_index": m["lane_index"].to_numpy(float), "is_member": True})


def _background_rows(bg: pd.DataFrame, dt: float, member_ids: set[str]) -> pd.DataFrame:
    b = bg.loc[~bg["vehicle_id"].astype(str).isin(member_ids)]
    num = {c: pd.to_numeric(b[c], errors="coerce").to_numpy(float)
           for c in ("t", "x", "y", "heading", "v", "length", "width")}
    ok = np.isfinite(np.column_stack([num[c] for c in ("t", "x", "y", "heading", "length",
                                                       "width")])).all(axis=1)
    get = (lambda c: pd.to_numeric(b[c], errors="coerce").to_numpy(float)[ok]
           if c in b.columns else np.full(int(ok.sum()), np.nan))
    h, v = num["heading"][ok], np.nan_to_num(num["v"][ok])
    return pd.DataFrame({
        "t": num["t"][ok], "key": time_keys(num["t"][ok], dt),
        "vehicle_id": b["vehicle_id"].astype(str).to_numpy()[ok], "x": num["x"][ok],
        "y": num["y"][ok], "heading": h, "v": v, "vx": v * np.cos(h), "vy": v * np.sin(h),
        "length": num["length"][ok], "width": num["width"][ok], "s": get("s"),
        "d": get("d"), "lane_index": get("lane_index"), "is_member": False})


def _reduce_min(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    out = np.full(n, np.inf)
    ok = np.isfinite(values)
    np.minimum.at(out, idx[ok], values[ok])
    return out


def _argmin_per(idx: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Per group 0..n-1, the position in ``values`` of its smallest finite value (-1)."""
    out = np.full(n, -1, dtype=np.int64)
    ok = np.flatnonzero(np.isfinite(values))
    if ok.size == 0:
        return out
    order = ok[np.lexsort((values[ok], idx[ok]))]
    first = np.unique(idx[order], return_index=True)
    out[first[0]] = order[first[1]]
    return out


def _time_below(x: np.ndarray, thr: float, dt: float) -> float | None:
    if not (math.isfinite(dt) and dt > 0):
        return None
    return float(np.count_nonzero(x < thr) * dt)


def _finite_min(x: np.ndarray) -> float | None:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(x.min()) if x.size else None


def _interaction(M: pd.DataFrame, P: pd.DataFrame, st: AnalysisSettings,
                 road: bool) -> tuple[pd.DataFrame, dict[str, np.ndarray], int]:
    """Pairs member row x partner row at the same step; per-member-row minima."""
    n = len(M)
    ia, ib = tr.same_time_pairs(M["key"].to_numpy(), P["key"].to_numpy())
    mid, pid = M["vehicle_id"].to_numpy(), P["vehicle_id"].to_numpy()
    keep = mid[ia] != pid[ib]
    ia, ib = ia[keep], ib[keep]
    mx, my, px, py = (M["x"].to_numpy(), M["y"].to_numpy(), P["x"].to_numpy(),
                      P["y"].to_numpy())
    near = np.hypot(px[ib] - mx[ia], py[ib] - my[ia]) <= st.interaction_range_m
    ia, ib = ia[near], ib[near]
    clr = np.empty(ia.size)
    ttc = np.empty(ia.size)
    cols = ("x", "y", "heading", "length", "width")
    A = {c: M[c].to_numpy(float) for c in (*cols, "vx", "vy")}
    B = {c: P[c].to_numpy(float) for c in (*cols, "vx", "vy")}
    for k0 in range(0, ia.size, PAIR_CHUNK):
        a, b = ia[k0:k0 + PAIR_CHUNK], ib[k0:k0 + PAIR_CHUNK]
        ga = [A[c][a] for c in cols]
        gb = [B[c][b] for c in cols]
        clr[k0:k0 + a.size], ttc[k0:k0 + a.size] = tr.pair_measures(
            *ga, A["vx"][a], A["vy"][a], *gb, B["vx"][b], B["vy"][b],
            horizon=st.ttc2d_horizon_s)
    p_member = P["is_member"].to_numpy(bool)[ib]
    per: dict[str, np.ndarray] = {
        "clearance_m": _reduce_min(ia, clr, n),
        "clearance_members_m": _reduce_min(ia, np.where(p_member, clr, np.inf), n),
        "clearance_bg_m": _reduce_min(ia, np.where(p_member, np.inf, clr), n),
        "ttc2d_s": _reduce_min(ia, ttc, n),
    }
    pairs = pd.DataFrame({"ia": ia, "ib": ib, "clearance_m": clr, "ttc2d_s": ttc})
    nan = np.full(n, np.nan)
    per.update(lat_gap_m=nan, headway_s=nan, follower_headway_s=nan)
    if road:
        S = {c: M[c].to_numpy(float) for c in ("s", "d", "length", "width", "v")}
        Q = {c: P[c].to_numpy(float) for c in ("s", "d", "length", "width", "v")}
        sa, da, la, wa = (S[c][ia] for c in ("s", "d", "length", "width"))
        sb, db, lb, wb = (Q[c][ib] for c in ("s", "d", "length", "width"))
        lat = tr.lateral_gap(sa, da, la, wa, sb, db, lb, wb)
        per["lat_gap_m"] = _reduce_min(ia, lat, n)
        band = tr.in_lateral_band(da, wa, db, wb)
        ahead = np.where(band & (sb > sa), tr.gap_ahead(sa, la, sb, lb), np.nan)
        behind = np.where(band & (sb < sa), tr.gap_ahead(sb, lb, sa, la), np.nan)
        lead = _argmin_per(ia, ahead, n)
        foll = _argmin_per(ia, behind, n)
        has_l, has_f = lead >= 0, foll >= 0
        hw = np.full(n, np.nan)
        hw[has_l] = tr.time_headway(ahead[lead[has_l]], S["v"][has_l])
        fhw = np.full(n, np.nan)
        fhw[has_f] = tr.time_headway(behind[foll[has_f]], Q["v"][ib[foll[has_f]]])
        per.update(headway_s=hw, follower_headway_s=fhw)
        pairs["lat_gap_m"] = lat
    for k in ("clearance_m", "clearance_members_m", "clearance_bg_m", "ttc2d_s", "lat_gap_m"):
        per[k] = np.where(np.isinf(per[k]), np.nan, per[k])
    return pairs, per, int(ia.size)


def _near_window(M: pd.DataFrame, rng: float) -> pd.DataFrame:
    """Per step: the formation's extent along the road (rearmost rear bumper, foremost
    front bumper) and the window ``rng`` beyond it on either side."""
    m = M.dropna(subset=["s"])
    g = pd.DataFrame({"key": m["key"], "rear": m["s"] - 0.5 * m["length"],
                      "front": m["s"] + 0.5 * m["length"]}).groupby("key")
    return pd.DataFrame({"rear": g["rear"].min(), "front": g["front"].max()}).assign(
        w_lo=lambda w: w["rear"] - rng, w_hi=lambda w: w["front"] + rng)


def _near_rows(bg: pd.DataFrame, win: pd.DataFrame, dt: float) -> pd.DataFrame:
    """Background rows whose centre is inside the formation's window at their step, with
    ``where``: behind (front bumper behind the formation's rear), ahead (rear bumper
    ahead of its front) or alongside."""
    if bg is None or win.empty or "s" not in bg.columns:
        return pd.DataFrame(columns=["vehicle_id", "key", "v", "lane_index", "where"])
    b = bg.assign(key=time_keys(pd.to_numeric(bg["t"], errors="coerce"), dt))
    b = b.join(win, on="key", how="inner")
    s = pd.to_numeric(b["s"], errors="coerce")
    b = b.loc[(s >= b["w_lo"]) & (s <= b["w_hi"])].copy()
    s = pd.to_numeric(b["s"], errors="coerce")
    half = 0.5 * pd.to_numeric(b.get("length", pd.Series(0.0, index=b.index)),
                               errors="coerce").fillna(0.0)
    b["where"] = np.where(s + half < b["rear"], "behind",
                          np.where(s - half > b["front"], "ahead", "alongside"))
    return b


def _mean(x) -> float | None:
    x = pd.to_numeric(pd.Series(x), errors="coerce").to_numpy(float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else None


def compute_traffic(data: RunData, settings: AnalysisSettings,
                    baseline: BaselineData | None = None) -> TrafficAnalysis:
    """Compute every traffic metric of a loaded run.

    Parameters
    ----------
    data : RunData
        Output of :func:`analysis.load.load_run`.
    settings : AnalysisSettings
        Thresholds, interaction range, TTC horizon (see :mod:`analysis.summary`).
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
    tables = data.tables
    bg = tables.get("background")
    ev = tables.get("events")
    ssm = tables.get("ssm")
    traj = data.trajectories
    t_first, t_last = float(traj["t"].min()), float(traj["t"].max())

    # --- 2-D interaction between members and every vehicle near them -------------------
    M = member_rows(data, fp, dt)
    road = bool(len(M)) and np.isfinite(M[["s", "d"]].to_numpy(float)).any()
    bg_ok = bg is not None and all(c in bg.columns for c in _BG_GEOMETRY)
    if bg is None:
        unavailable["background"] = "background.parquet missing: only member-member pairs"
    elif not bg_ok:
        miss = [c for c in _BG_GEOMETRY if c not in bg.columns]
        unavailable["background"] = f"background.parquet lacks {', '.join(miss)}"
    B = _background_rows(bg, dt, id_set) if bg_ok else M.iloc[:0]
    road_bg = road and bg_ok and "s" in bg.columns and "d" in bg.columns
    if not road:
        unavailable["lateral gap / headway"] = ("no road coordinates s, d in the "
                                                "trajectories (not a road run)")
    P = pd.concat([B, M], ignore_index=True) if len(B) else M
    series = pd.DataFrame({"t": M["t"], "vehicle_id": M["vehicle_id"]})
    if len(M):
        pairs, per, n_pairs = _interaction(M, P, st, road)
        for k, v in per.items():
            series[k] = v
        run["n_pairs"] = n_pairs
    else:
        pairs = pd.DataFrame(columns=["ia", "ib", "clearance_m", "ttc2d_s"])
        for k in ("clearance_m", "clearance_members_m", "clearance_bg_m", "ttc2d_s",
                  "lat_gap_m", "headway_s", "follower_headway_s"):
            series[k] = np.nan
        unavailable["interaction"] = "no member row with a finite pose"
    pid = P["vehicle_id"].to_numpy() if len(P) else np.array([], dtype=object)
    ptime = M["t"].to_numpy() if len(M) else np.array([])
    mids = M["vehicle_id"].to_numpy() if len(M) else np.array([], dtype=object)
    for m_id in ids:
        sel = mids == m_id
        if not sel.any():
            continue
        s = series.loc[sel]
        row = mem.loc[m_id]
        row["clearance_min_m"] = _finite_min(s["clearance_m"])
        row["clearance_members_min_m"] = _finite_min(s["clearance_members_m"])
        row["clearance_bg_min_m"] = _finite_min(s["clearance_bg_m"])
        row["lat_gap_min_m"] = _finite_min(s["lat_gap_m"])
        row["ttc2d_min_s"] = _finite_min(s["ttc2d_s"])
        pm = pairs.loc[mids[pairs["ia"].to_numpy(int)] == m_id] if len(pairs) else pairs
        for key, col in (("clearance_min", "clearance_m"), ("ttc2d_min", "ttc2d_s")):
            vals = pm[col].to_numpy(float) if len(pm) else np.array([])
            if np.isfinite(vals).any():
                j = int(np.argmin(np.where(np.isfinite(vals), vals, np.inf)))
                row[f"{key}_with"] = str(pid[int(pm["ib"].iloc[j])])
                row[f"{key}_t_s"] = float(ptime[int(pm["ia"].iloc[j])])
        row["t_clearance_below_s"] = _time_below(s["clearance_m"].to_numpy(float),
                                                 st.clearance_threshold_m, dt)
        row["t_ttc2d_below_s"] = _time_below(s["ttc2d_s"].to_numpy(float),
                                             st.ttc2d_threshold_s, dt)
        if road:
            row["t_lat_gap_below_s"] = _time_below(s["lat_gap_m"].to_numpy(float),
                                                   st.lateral_gap_threshold_m, dt)
            hw = s["headway_s"].to_numpy(float)
            row["headway_min_s"] = _finite_min(hw)
            row["headway_mean_s"] = _mean(hw)
            row["t_headway_below_s"] = _time_below(hw, st.headway_threshold_s, dt)
            fhw = s["follower_headway_s"].to_numpy(float)
            row["follower_headway_min_s"] = _finite_min(fhw)
            row["t_follower_headway_below_s"] = _time_below(fhw, st.headway_threshold_s, dt)
        mem.loc[m_id] = row
    for k in ("clearance_min_m", "clearance_members_min_m", "clearance_bg_min_m",
              "lat_gap_min_m", "ttc2d_min_s", "headway_min_s", "follower_headway_min_s"):
        run[k] = _finite_min(pd.to_numeric(mem[k], errors="coerce"))
    for k in ("t_clearance_below_s", "t_lat_gap_below_s", "t_ttc2d_below_s",
              "t_headway_below_s", "t_follower_headway_below_s"):
        col = pd.to_numeric(mem[k], errors="coerce")
        run[k] = float(col.max()) if col.notna().any() else None

    # --- background speed and time loss near the formation -----------------------------
    win = _near_window(M, st.interaction_range_m) if road else pd.DataFrame()
    near = pd.DataFrame()
    if bg_ok:
        b_all = bg.loc[~bg["vehicle_id"].astype(str).isin(id_set)]
        run["bg_n_vehicles"] = int(b_all["vehicle_id"].nunique())
        if math.isfinite(dt) and dt > 0:
            v = pd.to_numeric(b_all["v"], errors="coerce")
            loss = v.groupby(b_all["vehicle_id"].astype(str)).apply(
                lambda x: float(tr.time_loss(x.to_numpy(float), dt)))
            run["bg_time_loss_total_s"] = float(loss.sum()) if len(loss) else 0.0
            run["bg_time_loss_mean_s"] = float(loss.mean()) if len(loss) else None
        if road_bg:
            near = _near_rows(b_all, win, dt)
            run["bg_n_vehicles_near"] = int(near["vehicle_id"].nunique())
            run["bg_speed_mean_near_mps"] = _mean(near["v"])
            for w in ("behind", "alongside", "ahead"):
                run[f"bg_speed_mean_{w}_mps"] = _mean(near.loc[near["where"] == w, "v"])
            if len(near):
                lanes = near.assign(lane=pd.to_numeric(near["lane_index"], errors="coerce"))
                by = lanes.dropna(subset=["lane"]).groupby("lane")["v"].mean()
                run["bg_speed_mean_by_lane_mps"] = {str(int(k)): float(x)
                                                    for k, x in by.items()}

    # --- events ---------------------------------------------------------------------------
    if ev is None or not {"kind", "vehicle_id"} <= set(ev.columns):
        unavailable["events"] = ("events.parquet missing" if ev is None
                                 else "events.parquet lacks kind / vehicle_id")
    else:
        e = ev.copy()
        for c in ("kind", "vehicle_id", "other_id"):
            e[c] = e[c].astype(str) if c in e.columns else ""
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

    # --- SSM conflicts (SUMO's device) and conflicts from the recording ----------------------
    bg_keys = set(zip(B["vehicle_id"], B["key"])) if bg_ok else None
    member_s = M[["t", "vehicle_id", "s"]] if len(M) else None
    sr = ssm_section(ssm, ids, t_first, t_last, st, bg_keys, dt, ev, member_s)
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

    # --- baseline twin ----------------------------------------------------------------------
    base_tab = None
    if baseline is not None:
        issues += list(baseline.issues)
        run["baseline_run_dir"] = str(baseline.run_dir)
        bm = baseline.meta
        for key in ("seed",):
            if bm and meta and bm.get(key) != meta.get(key):
                issues.append(Issue("warning", "baseline_mismatch", f"baseline:{key}",
                                    f"{key} {bm.get(key)!r} differs from this run's "
                                    f"{meta.get(key)!r}: vehicles are not the same"))
        name_b = (bm.get("scenario") or {}).get("name") if isinstance(bm.get("scenario"),
                                                                      dict) else None
        name_r = (meta.get("scenario") or {}).get("name") if isinstance(
            meta.get("scenario"), dict) else None
        if name_b and name_r and name_b != name_r:
            issues.append(Issue("warning", "baseline_mismatch", "baseline:scenario",
                                f"scenario {name_b!r} differs from this run's {name_r!r}"))
        bb = baseline.background
        vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, "s"].to_numpy(float)
        vc = vc[np.isfinite(vc)]
        if vc.size < 2:
            ms = M["s"].to_numpy(float) if len(M) else np.array([])
            vc = ms[np.isfinite(ms)]
        if bb is None or not {"t", "vehicle_id", "s"} <= set(bb.columns):
            unavailable["baseline"] = "the baseline run has no usable background.parquet"
        elif not bg_ok or "s" not in bg.columns:
            unavailable["baseline"] = "this run has no usable background.parquet"
        elif vc.size < 2 or not vc.max() > vc.min():
            unavailable["baseline"] = "the formation's road section is unknown (no s)"
        else:
            s_a, s_b = float(vc.min()), float(vc.max())
            run["baseline_section_m"] = [s_a, s_b]
            b_run = bg.loc[~bg["vehicle_id"].astype(str).isin(id_set)]
            run["baseline_n_common"] = len(set(b_run["vehicle_id"].astype(str))
                                           & set(bb["vehicle_id"].astype(str)))
            base_tab = tr.baseline_comparison(b_run, bb, s_a, s_b,
                                              st.baseline_min_length_m)
            ok = base_tab.dropna(subset=["tt_run_s", "tt_base_s"])
            run["baseline_n_compared"] = int(len(ok))
            run["baseline_n_full_section"] = int(ok["full_section"].sum())
            if len(ok):
                run["baseline_tt_run_mean_s"] = float(ok["tt_run_s"].mean())
                run["baseline_tt_base_mean_s"] = float(ok["tt_base_s"].mean())
                run["baseline_delta_mean_s"] = float(ok["delta_s"].mean())
                run["baseline_delta_max_s"] = float(ok["delta_s"].max())
                run["baseline_delta_total_s"] = float(ok["delta_s"].sum())
                run["baseline_v_run_mps"] = float(ok["length_m"].sum() / ok["tt_run_s"].sum())
                run["baseline_v_base_mps"] = float(ok["length_m"].sum()
                                                   / ok["tt_base_s"].sum())
            else:
                issues.append(Issue("warning", "baseline_empty", "baseline",
                                    "no vehicle was recorded over at least "
                                    f"{st.baseline_min_length_m:g} m of the section in both "
                                    "runs"))
            if road and "s" in bb.columns:
                nb = _near_rows(bb, win, dt)
                run["baseline_bg_speed_mean_near_mps"] = _mean(nb["v"]) if len(nb) else None
                if run["baseline_bg_speed_mean_near_mps"] is not None and \
                        run["bg_speed_mean_near_mps"] is not None:
                    run["baseline_bg_speed_delta_near_mps"] = (
                        run["bg_speed_mean_near_mps"] - run["baseline_bg_speed_mean_near_mps"])
    for c in ("ssm_n_conflicts", "conflict_n", "n_cut_ins", "n_lane_changes", "n_collisions",
              "n_teleports"):
        mem[c] = [None if v is None or (isinstance(v, float) and math.isnan(v)) else int(v)
                  for v in mem[c]]
    return TrafficAnalysis(run=run, members=mem, ssm=sr.table, member_conflicts=sr.member_conflicts,
                           ssm_extremes=sr.extremes, conflicts=conf_tab, baseline=base_tab, series=series, unavailable=unavailable,
                           issues=tuple(issues))
