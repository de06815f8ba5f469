"""Member-vs-vehicle pairs of each time step: rows as rectangles, per-sample minima of
clearance, 2-D TTC, lateral gap and headways, and the per-member metrics built from them.

Part of the per-run traffic computation (:mod:`analysis.runs.traffic_run`); the measures are the
pure functions of :mod:`analysis.metrics.traffic`. Definitions: ``docs/metrics.md``, section
"Traffic interaction".
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
import pandas as pd

from analysis.load.run_data import RunData
from analysis.metrics import traffic as tr
from analysis.metrics.conflicts import time_keys
from analysis.runs.near_formation import finite_mean
from analysis.runs.settings import AnalysisSettings
from run_contract.columns import VIRTUAL_CAR_ID

__all__ = ["PAIR_CHUNK", "member_rows"]

PAIR_CHUNK = 200_000
"""Vehicle pairs evaluated per vectorised batch (bounds memory on long runs) [-]."""


def member_rows(data: RunData, fp: tr.Footprint | Mapping[str, tr.Footprint],
                dt: float) -> pd.DataFrame:
    """Members' rows as rectangles: body centre, velocity, road coordinates.

    Parameters
    ----------
    data : RunData
        The loaded run.
    fp : Footprint or mapping of member id to Footprint
        Members' body outlines: one for all, or each member's own
        (:func:`analysis.metrics.traffic.member_footprints`; a member missing from the mapping
        gets the first one's).
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
    length, width, front = _outline_columns(m["vehicle_id"], fp)
    xc, yc = tr.body_centre(m["x"], m["y"], h, front, length)
    v = np.nan_to_num(m["v"].to_numpy(float))
    beta = np.nan_to_num(m["beta"].to_numpy(float))
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID, ["t", "heading"]]
    vc_head = pd.Series(vc["heading"].to_numpy(float), index=time_keys(vc["t"], dt))
    vc_head = vc_head[~vc_head.index.duplicated()]
    rel = h - np.nan_to_num(vc_head.reindex(key).to_numpy(float), nan=0.0) if len(vc) \
        else np.zeros_like(h)
    off = front - 0.5 * length
    return pd.DataFrame({
        "t": t, "key": key, "vehicle_id": m["vehicle_id"].to_numpy(str), "x": xc, "y": yc,
        "heading": h, "v": v, "vx": v * np.cos(h + beta), "vy": v * np.sin(h + beta),
        "length": length, "width": width,
        "s": m["s"].to_numpy(float) + off * np.cos(rel),
        "d": m["d"].to_numpy(float) + off * np.sin(rel),
        "lane_index": m["lane_index"].to_numpy(float), "is_member": True})


def _outline_columns(vehicle_id: pd.Series, fp: tr.Footprint | Mapping[str, tr.Footprint]
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-row body length, width and CoG-to-front-bumper distance [m]."""
    table = {} if isinstance(fp, tr.Footprint) else dict(fp)
    default = fp if isinstance(fp, tr.Footprint) else next(iter(table.values()), None)
    ids = vehicle_id.astype(str).to_numpy()
    out = np.empty((3, len(ids)))
    for mid in np.unique(ids):
        f = table.get(mid, default)
        out[:, ids == mid] = np.array([f.length, f.width, f.cog_to_front])[:, None]
    return out[0], out[1], out[2]


def background_rows(bg: pd.DataFrame, dt: float, member_ids: set[str]) -> pd.DataFrame:
    """The rows of ``bg`` that are not members (``member_ids``) and have a finite time, pose
    and size, as pair rows: the step's time key (``dt`` [s]), speed [m/s] (NaN read as 0)
    and its components, Frenet ``s``, ``d`` and lane (NaN when not recorded)."""
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
        ma = tr.Moving(*(A[c][a] for c in (*cols, "vx", "vy")))
        mb = tr.Moving(*(B[c][b] for c in (*cols, "vx", "vy")))
        clr[k0:k0 + a.size], ttc[k0:k0 + a.size] = tr.pair_measures(ma, mb, horizon=st.ttc2d_horizon_s)
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


def member_interaction(M: pd.DataFrame, P: pd.DataFrame, ids: list[str], st: AnalysisSettings,
                       dt: float, road: bool, mem: pd.DataFrame,
                       run: dict[str, Any]) -> tuple[pd.DataFrame, str | None]:
    """Per-sample series and the members' interaction metrics (filled into ``mem`` and ``run``).

    ``M`` are the members' rows (:func:`member_rows`), ``P`` every partner row (background and
    members); ``road`` says whether road coordinates exist. Returns the per-sample ``series``
    and why the interaction is unavailable (None when computed).
    """
    series = pd.DataFrame({"t": M["t"], "vehicle_id": M["vehicle_id"]})
    missing = None
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
        missing = "no member row with a finite pose"
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
            row["headway_mean_s"] = finite_mean(hw)
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

    return series, missing
