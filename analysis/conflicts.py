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

import numpy as np
import pandas as pd

__all__ = [
    "SSM_RANGE_M", "TTC_THRESHOLD_S", "DRAC_THRESHOLD_MPS2", "PET_THRESHOLD_S", "FOLLOW_DEPTH",
    "CONFLICT_COLUMNS", "following_pairs", "following_measures", "encounters",
    "lane_change_pet", "recorded_conflicts", "compare_with_ssm",
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


def following_pairs(key, lane, s, d, length, width, *, depth: int = FOLLOW_DEPTH,
                    max_gap: float = SSM_RANGE_M) -> tuple[np.ndarray, np.ndarray]:
    """Follower and leader row indices of every following pair.

    Parameters
    ----------
    key : array_like of int
        Time step of each row.
    lane : array_like
        SUMO lane index of each row (NaN rows are never paired).
    s, d : array_like
        Body centre along and across the road [m].
    length, width : array_like
        Body size [m].
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
    order = ok[np.lexsort((s[ok], lane[ok], key[ok]))]
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
    """Gap [m], TTC [s] and DRAC [m/s^2] of follower/leader pairs (body centres ``s``, lengths
    ``l`` [m], speeds ``v`` [m/s]).

    TTC is ``gap / (v_f - v_l)`` where the follower is faster (0 where the gap is <= 0) and
    NaN otherwise; DRAC is ``(v_f - v_l)^2 / (2 gap)`` where the follower is faster and the gap
    positive, NaN otherwise.

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


def encounters(f_id, l_id, key, t, gap, ttc, drac) -> pd.DataFrame:
    """Runs of consecutive steps of each (follower, leader) pair, with their extremes.

    Returns
    -------
    DataFrame
        One row per encounter: ``follower``, ``leader``, ``begin``, ``end`` [s], ``k_begin``
        (step of the first sample), ``min_ttc`` [s] and ``min_ttc_time``, ``max_drac`` [m/s^2]
        and ``max_drac_time``, ``min_gap`` [m] (NaN where a measure never exists).
    """
    df = pd.DataFrame({"follower": np.asarray(f_id, dtype=object), "leader": np.asarray(l_id, dtype=object),
                       "key": np.asarray(key, np.int64), "t": np.asarray(t, float),
                       "gap": gap, "ttc": ttc, "drac": drac})
    if df.empty:
        return pd.DataFrame(columns=["follower", "leader", "begin", "end", "k_begin", "min_ttc",
                                     "min_ttc_time", "max_drac", "max_drac_time", "min_gap"])
    df = df.sort_values(["follower", "leader", "key"], kind="stable").reset_index(drop=True)
    same = (df["follower"].to_numpy() == np.roll(df["follower"].to_numpy(), 1)) & \
           (df["leader"].to_numpy() == np.roll(df["leader"].to_numpy(), 1)) & \
           (np.diff(df["key"].to_numpy(), prepend=-10) == 1)
    same[0] = False
    df["enc"] = np.cumsum(~same)
    g = df.groupby("enc", sort=True)
    out = g.agg(follower=("follower", "first"), leader=("leader", "first"), begin=("t", "min"),
                end=("t", "max"), k_begin=("key", "min"), min_ttc=("ttc", "min"),
                max_drac=("drac", "max"), min_gap=("gap", "min"))
    enc, t = df["enc"].to_numpy(), df["t"].to_numpy()
    out["min_ttc_time"] = _time_of_extreme(enc, df["ttc"].to_numpy(float), t, out.index, False)
    out["max_drac_time"] = _time_of_extreme(enc, df["drac"].to_numpy(float), t, out.index, True)
    return out.reset_index(drop=True)


def _time_of_extreme(group: np.ndarray, x: np.ndarray, t: np.ndarray, labels, largest: bool) -> np.ndarray:
    """Per group label, the time of the first smallest (largest) finite value of ``x`` (NaN)."""
    ok = np.flatnonzero(np.isfinite(x))
    order = ok[np.lexsort((t[ok], -x[ok] if largest else x[ok], group[ok]))]
    first_lab, first = np.unique(group[order], return_index=True)
    return pd.Series(t[order[first]], index=first_lab).reindex(labels).to_numpy(float)


def lane_change_pet(rows: pd.DataFrame, f_idx: np.ndarray, l_idx: np.ndarray) -> pd.DataFrame:
    """PET of the lane changes in the recording.

    At the first step ``k`` a vehicle is seen on a new lane (the step before it was on another
    lane), each following pair it forms there with its immediate neighbour (it as follower or
    as leader) gets ``PET = t_f(s*) - t_k``: ``s*`` is the leader's rear at ``t_k`` and
    ``t_f(s*)`` the time the follower's front reaches it, interpolated in the follower's own
    record (NaN if its record ends before).

    Parameters
    ----------
    rows : DataFrame
        ``vehicle_id``, ``key``, ``t``, ``lane_index``, ``s``, ``length``, one row per vehicle
        per step.
    f_idx, l_idx : ndarray
        Following pairs (row indices into ``rows``), as from :func:`following_pairs`.

    Returns
    -------
    DataFrame
        ``follower``, ``leader``, ``k`` (step of the change), ``pet`` [s].
    """
    vid = rows["vehicle_id"].to_numpy(dtype=object)
    key = rows["key"].to_numpy(np.int64)
    lane = rows["lane_index"].to_numpy(float)
    s_front = rows["s"].to_numpy(float) + 0.5 * rows["length"].to_numpy(float)
    s_rear = rows["s"].to_numpy(float) - 0.5 * rows["length"].to_numpy(float)
    t = rows["t"].to_numpy(float)
    order = np.lexsort((key, vid.astype(str)))
    a, b = order[:-1], order[1:]
    changed = np.zeros(len(rows), bool)
    changed[b] = (vid[a] == vid[b]) & (key[b] == key[a] + 1) & np.isfinite(lane[a]) & \
        np.isfinite(lane[b]) & (lane[a] != lane[b])
    pick = changed[f_idx] | changed[l_idx]
    f_idx, l_idx = f_idx[pick], l_idx[pick]
    # only the immediate neighbour: the closest leader of each follower row and vice versa
    gap = s_rear[l_idx] - s_front[f_idx]
    df = pd.DataFrame({"f": f_idx, "l": l_idx, "gap": gap})
    df = df.loc[df.groupby("f")["gap"].idxmin()]
    df = df.loc[df.groupby("l")["gap"].idxmin()]
    if df.empty:
        return pd.DataFrame(columns=["follower", "leader", "k", "pet"])
    sorted_ids = vid[order].astype(str)
    by_vehicle = {v: order[np.searchsorted(sorted_ids, v, "left"):np.searchsorted(sorted_ids, v, "right")]
                  for v in set(vid[df["f"].to_numpy()])}
    pet = np.full(len(df), np.nan)
    for j, (fi, li) in enumerate(zip(df["f"].to_numpy(), df["l"].to_numpy())):
        own = by_vehicle[vid[fi]]
        own = own[t[own] >= t[fi]]
        target = s_rear[li]
        sf = np.maximum.accumulate(s_front[own])
        if sf.size and sf[-1] >= target:
            pet[j] = float(np.interp(target, sf, t[own])) - t[fi]
    return pd.DataFrame({"follower": vid[df["f"].to_numpy()], "leader": vid[df["l"].to_numpy()],
                         "k": key[df["f"].to_numpy()], "pet": pet})


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
    ttc_threshold, drac_threshold, pet_threshold : float
        An encounter is a conflict when its minimum TTC [s] is below, its maximum DRAC [m/s^2]
        above, or its PET [s] below these.

    Returns
    -------
    DataFrame
        One row per conflict, columns :data:`CONFLICT_COLUMNS`, by ``begin``.
    """
    rows = rows.reset_index(drop=True)
    col = {c: rows[c].to_numpy(float) for c in ("s", "d", "v", "length", "width", "lane_index")}
    key = rows["key"].to_numpy(np.int64)
    fi, li = following_pairs(key, col["lane_index"], col["s"], col["d"], col["length"], col["width"])
    gap, ttc, drac = following_measures(col["s"][fi], col["length"][fi], col["v"][fi],
                                        col["s"][li], col["length"][li], col["v"][li])
    vid = rows["vehicle_id"].to_numpy(dtype=object)
    enc = encounters(vid[fi], vid[li], key[fi], rows["t"].to_numpy(float)[fi], gap, ttc, drac)
    pet = lane_change_pet(rows, fi, li)
    dt = float(np.median(np.diff(np.unique(rows["t"].to_numpy(float))))) if len(rows) > 1 else 0.0
    enc["pet"], enc["pet_time"] = np.nan, np.nan
    if len(pet) and len(enc):
        m = enc.reset_index().merge(pet, left_on=["follower", "leader", "k_begin"],
                                    right_on=["follower", "leader", "k"], how="inner")
        enc.loc[m["index"].to_numpy(), "pet"] = m["pet_y"].to_numpy() if "pet_y" in m else m["pet"].to_numpy()
        enc.loc[m["index"].to_numpy(), "pet_time"] = enc.loc[m["index"].to_numpy(), "begin"].to_numpy()
    del dt
    hit = (enc["min_ttc"] < ttc_threshold) | (enc["max_drac"] > drac_threshold) | \
        (enc["pet"] < pet_threshold)
    out = enc.loc[hit.fillna(False)].copy()
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
        with :func:`analysis.traffic.merge_ssm_duplicates`.
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
