"""Conflict measures from the recording: TTC, DRAC and PET of following pairs, vectorised.

The same measures as SUMO's SSM device (docs/metrics.md, "Conflicts from the recording"),
computed afterwards on ``trajectories.parquet`` (members) and ``background.parquet`` (SUMO's
vehicles within ``traffic.record_radius`` of a member) instead of by a device on every vehicle:

* a *following pair* at a step is a follower and one of the ``FOLLOW_DEPTH`` vehicles ahead of
  it on the same SUMO lane (``lane_index``) whose bodies overlap across the road and whose
  bumper-to-bumper gap is at most ``SSM_RANGE_M``;
* ``TTC = gap / (v_f - v_l)`` when the follower is faster (constant speeds), 0 when the gap is
  <= 0; ``DRAC = (v_f - v_l)^2 / (2 gap)`` (the deceleration the follower needs to match the
  leader's speed within the gap), undefined when the gap is <= 0;
* an *encounter* is a run of consecutive steps in which a pair follows; it is a *conflict*
  when its minimum TTC is below 3 s, its maximum DRAC above 3 m/s^2 or its PET below 2 s
  (SUMO's thresholds);
* PET (post-encroachment time) of a lane change: when a vehicle enters a lane, for the pair it
  forms there with its new immediate leader or follower, the time from the leader's rear
  leaving the point it occupies at the change to the follower's front reaching that point.
  On a motorway this is the merge conflict of a lane change (SUMO's device computes PET only
  at junctions).

Pure functions over arrays and DataFrames; no file is read here.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = [
    "SSM_RANGE_M", "TTC_THRESHOLD_S", "DRAC_THRESHOLD_MPS2", "PET_THRESHOLD_S", "FOLLOW_DEPTH",
    "CONFLICT_COLUMNS", "following_pairs", "following_measures", "encounters",
    "lane_change_pet", "recorded_conflicts", "compare_with_ssm", "time_keys",
]

SSM_RANGE_M = 50.0
"""Largest bumper-to-bumper gap of a following pair [m] (``--device.ssm.range`` of the runs)."""
TTC_THRESHOLD_S = 3.0
"""An encounter with a smaller minimum TTC is a conflict [s] (SUMO SSM threshold)."""
DRAC_THRESHOLD_MPS2 = 3.0
"""An encounter with a larger maximum DRAC is a conflict [m/s^2] (SUMO SSM threshold)."""
PET_THRESHOLD_S = 2.0
"""A lane change with a smaller PET is a conflict [s] (SUMO SSM threshold)."""
FOLLOW_DEPTH = 3
"""A follower is paired with up to this many vehicles ahead of it in its lane [-]."""

CONFLICT_COLUMNS = ("follower", "leader", "begin", "end", "min_ttc", "min_ttc_time", "max_drac",
                    "max_drac_time", "pet", "pet_time", "min_gap", "member_involved")
"""Columns of :func:`recorded_conflicts`' table (times [s], TTC/PET [s], DRAC [m/s^2], gap [m])."""


def time_keys(t, dt: float) -> np.ndarray:
    """Integer step index of each time, to match rows of different tables.

    Parameters
    ----------
    t : array_like
        Times on the formation clock [s].
    dt : float
        Sample spacing [s]; when not finite, microseconds are used.

    Returns
    -------
    ndarray of int64
        ``round(t / dt)``.

    Examples
    --------
    >>> time_keys([0.0, 0.15000000000000002, 0.3], 0.05).tolist()
    [0, 3, 6]
    """
    t = np.asarray(t, float)
    step = dt if (dt is not None and math.isfinite(dt) and dt > 0) else 1e-6
    return np.round(t / step).astype(np.int64)


def following_pairs(key, lane, s, d, length, width, *, depth: int = FOLLOW_DEPTH,
                    max_gap: float = SSM_RANGE_M) -> tuple[np.ndarray, np.ndarray]:
    """Follower and leader row indices of every following pair.

    Parameters
    ----------
    key : array_like of int
        Time step of each row.
    lane : array_like
        SUMO lane index of each row (NaN rows are never paired).
    s : array_like
        Body centre along the road [m].
    d : array_like
        Body centre across the road [m].
    length : array_like
        Body length [m].
    width : array_like
        Body width [m].
    depth : int
        Vehicles ahead in the lane each follower is paired with.
    max_gap : float
        Largest bumper-to-bumper gap [m].

    Returns
    -------
    (ndarray, ndarray)
        Row indices of followers and of their leaders (same step, same lane, bodies
        overlapping across the road, leader's centre ahead, gap <= ``max_gap``).

    Examples
    --------
    >>> f, l = following_pairs([0, 0, 0], [1, 1, 0], [0.0, 20.0, 10.0], [0, 0, 0], [4.5] * 3,
    ...                        [1.8] * 3)
    >>> f.tolist(), l.tolist()
    ([0], [1])
    """
    key, lane = np.asarray(key, np.int64), np.asarray(lane, float)
    s, d = np.asarray(s, float), np.asarray(d, float)
    length, width = np.asarray(length, float), np.asarray(width, float)
    ok = np.flatnonzero(np.isfinite(lane) & np.isfinite(s) & np.isfinite(d))
    lanes = np.unique(lane[ok])
    slot = (key[ok] - (key[ok].min() if ok.size else 0)) * max(lanes.size, 1) + np.searchsorted(lanes, lane[ok])
    order = ok[np.lexsort((s[ok], slot))]
    fs, ls = [], []
    for k in range(1, depth + 1):
        a, b = order[:-k], order[k:]
        keep = (key[a] == key[b]) & (lane[a] == lane[b]) & (s[b] > s[a])
        a, b = a[keep], b[keep]
        gap = (s[b] - 0.5 * length[b]) - (s[a] + 0.5 * length[a])
        keep = (np.abs(d[a] - d[b]) < 0.5 * (width[a] + width[b])) & (gap <= max_gap)
        fs.append(a[keep])
        ls.append(b[keep])
    return np.concatenate(fs), np.concatenate(ls)


def following_measures(s_f, l_f, v_f, s_l, l_l, v_l) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gap, TTC and DRAC of follower/leader pairs.

    Parameters
    ----------
    s_f : array_like
        Follower's body centre along the road [m].
    l_f : array_like
        Follower's length [m].
    v_f : array_like
        Follower's speed [m/s].
    s_l : array_like
        Leader's body centre along the road [m].
    l_l : array_like
        Leader's length [m].
    v_l : array_like
        Leader's speed [m/s].

    Returns
    -------
    (ndarray, ndarray, ndarray)
        Bumper-to-bumper gap [m]; TTC [s], ``gap / (v_f - v_l)`` where the follower is faster
        (0 where the gap is <= 0), NaN otherwise; DRAC [m/s^2], ``(v_f - v_l)^2 / (2 gap)``
        where the follower is faster and the gap positive, NaN otherwise.

    Examples
    --------
    >>> g, ttc, drac = following_measures(0.0, 4.0, 30.0, 24.0, 4.0, 20.0)
    >>> float(g), float(ttc), float(drac)
    (20.0, 2.0, 2.5)
    """
    s_f, l_f, v_f, s_l, l_l, v_l = (np.asarray(x, float) for x in (s_f, l_f, v_f, s_l, l_l, v_l))
    gap = (s_l - 0.5 * l_l) - (s_f + 0.5 * l_f)
    dv = v_f - v_l
    closing = dv > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(closing, np.maximum(gap, 0.0) / dv, np.nan)
        drac = np.where(closing & (gap > 0), dv * dv / (2.0 * gap), np.nan)
    return gap, ttc, drac


def encounters(f_code, l_code, key, t, gap, ttc, drac) -> dict[str, np.ndarray]:
    """Runs of consecutive steps of each (follower, leader) pair, with their extremes.

    Parameters
    ----------
    f_code : array_like of int
        Follower of each pair sample (integer vehicle code).
    l_code : array_like of int
        Leader of each pair sample.
    key : array_like of int
        Step of each sample.
    t : array_like
        Time of each sample [s].
    gap : array_like
        Bumper-to-bumper gap [m] (:func:`following_measures`).
    ttc : array_like
        TTC [s].
    drac : array_like
        DRAC [m/s^2].

    Returns
    -------
    dict of ndarray
        One entry per encounter: ``follower``, ``leader`` (codes), ``begin``, ``end`` [s],
        ``k_begin`` (step of the first sample), ``min_ttc`` [s] and ``min_ttc_time``,
        ``max_drac`` [m/s^2] and ``max_drac_time``, ``min_gap`` [m] (NaN where a measure
        never exists).
    """
    f_code, l_code = np.asarray(f_code, np.int64), np.asarray(l_code, np.int64)
    key, t = np.asarray(key, np.int64), np.asarray(t, float)
    gap, ttc, drac = (np.asarray(x, float) for x in (gap, ttc, drac))
    names = ("follower", "leader", "begin", "end", "k_begin", "min_ttc", "min_ttc_time",
             "max_drac", "max_drac_time", "min_gap")
    if key.size == 0:
        return {k: np.empty(0) for k in names}
    n = int(max(f_code.max(), l_code.max())) + 1
    k0, span = int(key.min()), int(key.max() - key.min()) + 2
    pair = f_code * n + l_code
    o = np.argsort(pair * span + (key - k0), kind="stable")  # one int64 sort: by pair, then step
    pair, f_code, l_code, key, t, gap, ttc, drac = (x[o] for x in (pair, f_code, l_code, key, t, gap, ttc, drac))
    new = np.ones(key.size, bool)
    new[1:] = (pair[1:] != pair[:-1]) | (key[1:] != key[:-1] + 1)
    start = np.flatnonzero(new)
    last = np.append(start[1:], key.size) - 1
    enc = np.cumsum(new) - 1
    with np.errstate(invalid="ignore"):
        out = {"follower": f_code[start], "leader": l_code[start], "begin": t[start], "end": t[last],
               "k_begin": key[start], "min_ttc": np.fmin.reduceat(ttc, start),
               "max_drac": np.fmax.reduceat(drac, start), "min_gap": np.fmin.reduceat(gap, start)}
    out["min_ttc_time"] = _time_of_extreme(enc, ttc, t, start.size, False)
    out["max_drac_time"] = _time_of_extreme(enc, drac, t, start.size, True)
    return out


def _time_of_extreme(group: np.ndarray, x: np.ndarray, t: np.ndarray, n: int, largest: bool) -> np.ndarray:
    """Per group 0..n-1, the time of the first smallest (largest) finite value of ``x`` (NaN)."""
    out = np.full(n, np.nan)
    ok = np.flatnonzero(np.isfinite(x))
    order = ok[np.lexsort((t[ok], -x[ok] if largest else x[ok], group[ok]))]
    first_lab, first = np.unique(group[order], return_index=True)
    out[first_lab] = t[order[first]]
    return out


def lane_change_pet(code, key, t, lane, s, length, f_idx: np.ndarray, l_idx: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """PET of the lane changes in the recording.

    At the first step ``k`` a vehicle is seen on a new lane (the step before it was on another
    lane), each following pair it forms there with its immediate neighbour (it as follower or
    as leader) gets ``PET = t_f(s*) - t_k``: ``s*`` is the leader's rear at ``t_k`` and
    ``t_f(s*)`` the time the follower's front reaches it, interpolated in the follower's own
    record (NaN if its record ends before).

    Parameters
    ----------
    code : array_like of int
        Vehicle of each row (one vehicle at one step), as an integer code.
    key : array_like of int
        Step of each row.
    t : array_like
        Time of each row [s].
    lane : array_like
        SUMO lane index of each row.
    s : array_like
        Body centre along the road [m].
    length : array_like
        Body length [m].
    f_idx : ndarray
        Followers of the following pairs (row indices), as from :func:`following_pairs`.
    l_idx : ndarray
        Their leaders.

    Returns
    -------
    (ndarray, ndarray, ndarray, ndarray)
        Follower code, leader code, step of the change, PET [s].
    """
    code, key = np.asarray(code, np.int64), np.asarray(key, np.int64)
    t, lane = np.asarray(t, float), np.asarray(lane, float)
    s_front = np.asarray(s, float) + 0.5 * np.asarray(length, float)
    s_rear = np.asarray(s, float) - 0.5 * np.asarray(length, float)
    order = np.lexsort((key, code))
    a, b = order[:-1], order[1:]
    changed = np.zeros(code.size, bool)
    changed[b] = (code[a] == code[b]) & (key[b] == key[a] + 1) & np.isfinite(lane[a]) & \
        np.isfinite(lane[b]) & (lane[a] != lane[b])
    pick = changed[f_idx] | changed[l_idx]
    f_idx, l_idx = f_idx[pick], l_idx[pick]
    # only the immediate neighbour: the closest leader of each follower row and vice versa
    gap = s_rear[l_idx] - s_front[f_idx]
    o = np.lexsort((gap, f_idx))
    f_idx, l_idx, gap = f_idx[o], l_idx[o], gap[o]
    first = np.unique(f_idx, return_index=True)[1]
    f_idx, l_idx, gap = f_idx[first], l_idx[first], gap[first]
    o = np.lexsort((gap, l_idx))
    first = np.unique(l_idx[o], return_index=True)[1]
    f_idx, l_idx = f_idx[o][first], l_idx[o][first]
    sorted_codes = code[order]
    pet = np.full(f_idx.size, np.nan)
    for j, (fi, li) in enumerate(zip(f_idx, l_idx)):
        own = order[np.searchsorted(sorted_codes, code[fi], "left"):np.searchsorted(sorted_codes, code[fi], "right")]
        own = own[t[own] >= t[fi]]
        sf = np.maximum.accumulate(s_front[own])
        if sf.size and sf[-1] >= s_rear[li]:
            pet[j] = float(np.interp(s_rear[li], sf, t[own])) - t[fi]
    return code[f_idx], code[l_idx], key[f_idx], pet


def recorded_conflicts(rows: pd.DataFrame, members, *, ttc_threshold: float = TTC_THRESHOLD_S,
                       drac_threshold: float = DRAC_THRESHOLD_MPS2,
                       pet_threshold: float = PET_THRESHOLD_S) -> pd.DataFrame:
    """Conflicts among the recorded vehicles (members and background).

    Parameters
    ----------
    rows : DataFrame
        One row per vehicle per step: ``vehicle_id``, ``key`` (step), ``t`` [s], ``lane_index``,
        ``s``, ``d`` (body centre [m]), ``v`` [m/s], ``length``, ``width`` [m].
    members : collection of str
        Member ids (``member_involved``).
    ttc_threshold : float
        An encounter whose minimum TTC is below this is a conflict [s].
    drac_threshold : float
        An encounter whose maximum DRAC is above this is a conflict [m/s^2].
    pet_threshold : float
        A lane change whose PET is below this is a conflict [s].

    Returns
    -------
    DataFrame
        One row per conflict, columns :data:`CONFLICT_COLUMNS`, by ``begin``.
    """
    col = {c: rows[c].to_numpy(float) for c in ("t", "s", "d", "v", "length", "width", "lane_index")}
    key = rows["key"].to_numpy(np.int64)
    code, names = pd.factorize(rows["vehicle_id"].astype(str).to_numpy(dtype=object))
    fi, li = following_pairs(key, col["lane_index"], col["s"], col["d"], col["length"], col["width"])
    gap, ttc, drac = following_measures(col["s"][fi], col["length"][fi], col["v"][fi],
                                        col["s"][li], col["length"][li], col["v"][li])
    enc = encounters(code[fi], code[li], key[fi], col["t"][fi], gap, ttc, drac)
    pf, pl, pk, pv = lane_change_pet(code, key, col["t"], col["lane_index"], col["s"], col["length"], fi, li)
    n_codes = max(len(names), 1)
    enc_id = (enc["follower"].astype(np.int64) * n_codes + enc["leader"].astype(np.int64)) * (2**31) + \
        enc["k_begin"].astype(np.int64)
    pet_id = (pf * n_codes + pl) * (2**31) + pk
    pos = {v: i for i, v in enumerate(pet_id.tolist())}
    enc["pet"] = np.array([pv[pos[v]] if v in pos else np.nan for v in enc_id.tolist()], float)
    enc["pet_time"] = np.where(np.isfinite(enc["pet"]), enc["begin"], np.nan)
    with np.errstate(invalid="ignore"):
        hit = (enc["min_ttc"] < ttc_threshold) | (enc["max_drac"] > drac_threshold) | \
            (enc["pet"] < pet_threshold)
    out = pd.DataFrame({k: v[hit] for k, v in enc.items() if k != "k_begin"})
    names = np.asarray(names, dtype=object)
    out["follower"] = names[out["follower"].to_numpy(np.int64)] if len(out) else []
    out["leader"] = names[out["leader"].to_numpy(np.int64)] if len(out) else []
    mem = set(members)
    out["member_involved"] = out["follower"].isin(mem) | out["leader"].isin(mem)
    return out.sort_values(["begin", "follower", "leader"]).reset_index(drop=True)[list(CONFLICT_COLUMNS)]


def compare_with_ssm(ours: pd.DataFrame, ssm: pd.DataFrame, *, ttc_below: float = TTC_THRESHOLD_S,
                     tol_s: float = 0.2) -> pd.DataFrame:
    """Check recording-based conflicts against SUMO's SSM conflicts (the oracle).

    Parameters
    ----------
    ours : DataFrame
        :func:`recorded_conflicts` (or any table with ``follower``, ``leader``, ``begin``,
        ``end``, ``min_ttc``).
    ssm : DataFrame
        SUMO's conflicts (``ego``, ``foe``, ``begin``, ``end``, ``min_ttc``), e.g. merged
        with :func:`analysis.metrics.traffic.merge_ssm_duplicates`.
    ttc_below : float
        Only SUMO conflicts with ``min_ttc`` below this are checked [s].
    tol_s : float
        Largest accepted difference of the minimum TTC [s].

    Returns
    -------
    DataFrame
        One row per checked SUMO conflict: ``ego``, ``foe``, ``begin``, ``end``,
        ``ssm_min_ttc``, ``ours_min_ttc`` (smallest TTC of our conflicts of the same pair
        whose time span overlaps SUMO's; NaN if none), ``found`` (there is one) and ``within``
        (``|ours - ssm| <= tol_s``).
    """
    chk = ssm.loc[pd.to_numeric(ssm["min_ttc"], errors="coerce") < ttc_below]
    a = ours["follower"].astype(str).to_numpy()
    b = ours["leader"].astype(str).to_numpy()
    p1, p2 = np.minimum(a, b), np.maximum(a, b)
    rows = []
    for r in chk.itertuples(index=False):
        e, f = str(r.ego), str(r.foe)
        q1, q2 = min(e, f), max(e, f)
        sel = (p1 == q1) & (p2 == q2) & (ours["begin"].to_numpy(float) <= float(r.end)) & \
            (ours["end"].to_numpy(float) >= float(r.begin))
        v = ours["min_ttc"].to_numpy(float)[sel]
        v = v[np.isfinite(v)]
        mine = float(v.min()) if v.size else np.nan
        rows.append({"ego": e, "foe": f, "begin": float(r.begin), "end": float(r.end),
                     "ssm_min_ttc": float(r.min_ttc), "ours_min_ttc": mine, "found": bool(v.size),
                     "within": bool(v.size) and abs(mine - float(r.min_ttc)) <= tol_s})
    return pd.DataFrame(rows, columns=["ego", "foe", "begin", "end", "ssm_min_ttc", "ours_min_ttc",
                                       "found", "within"])
