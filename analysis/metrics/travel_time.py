"""Delays: time lost against a reference speed, section crossing and travel times, and the
comparison of background traffic with and without the formation.

Part of the traffic interaction measures (:mod:`analysis.metrics.traffic`); definitions in
``docs/metrics.md``.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["time_loss", "crossing_times", "section_travel_times", "baseline_comparison"]


def time_loss(v, dt: float, v_ref=None, axis: int = -1):
    """Time lost against a reference speed: ``sum (1 - v/v_ref) dt``.

    Parameters
    ----------
    v : array_like
        Speed samples [m/s], uniformly spaced (each sample stands for ``dt``).
    dt : float
        Sample spacing [s].
    v_ref : array_like, optional
        Reference speed [m/s] (broadcast against ``v`` without the time axis); default
        the largest speed along ``axis`` (the vehicle's own maximum recorded speed).
    axis : int
        Time axis.

    Returns
    -------
    ndarray or float
        Time lost [s]: the extra time the distance actually covered took compared with
        driving it at ``v_ref`` (SUMO's ``timeLoss`` uses the allowed speed instead of the
        maximum recorded one). Non-finite samples count as no loss.

    Examples
    --------
    >>> float(time_loss([20.0, 10.0, 20.0, 20.0], 1.0))  # one second at half speed
    0.5
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite sample spacing [s], got {dt!r}")
    v = np.moveaxis(np.asarray(v, float), axis, -1)
    if v_ref is None:
        with np.errstate(invalid="ignore"):
            v_ref = np.nanmax(np.where(np.isfinite(v), v, np.nan), axis=-1) if v.shape[-1] \
                else np.nan
    v_ref = np.asarray(v_ref, float)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        loss = np.where(np.isfinite(v) & (v_ref > 0), 1.0 - v / v_ref, 0.0)
    return np.sum(loss, axis=-1) * dt


def crossing_times(t, s, s_cross) -> np.ndarray:
    """When a vehicle first reaches positions along the road.

    Parameters
    ----------
    t : array_like
        Sample times of one vehicle, ascending [s].
    s : array_like
        Its position along the road [m] (small backward steps are ignored: the running
        maximum is used).
    s_cross : array_like
        Positions to reach [m].

    Returns
    -------
    ndarray
        Time [s] at which ``s`` first reaches each ``s_cross``, linearly interpolated
        between the samples around it; NaN when ``s_cross`` lies outside the recorded
        range ``[s[0], max s]``.

    Examples
    --------
    >>> crossing_times([0.0, 1.0, 2.0], [0.0, 10.0, 20.0], [5.0, 20.0, 30.0]).tolist()
    [0.5, 2.0, nan]
    """
    t, s = np.asarray(t, float), np.asarray(s, float)
    q = np.atleast_1d(np.asarray(s_cross, float))
    ok = np.isfinite(t) & np.isfinite(s)
    t, s = t[ok], s[ok]
    out = np.full(q.shape, np.nan)
    if t.size == 0:
        return out
    sm = np.maximum.accumulate(s)
    k = np.searchsorted(sm, q, side="left")
    inside = (q >= s[0]) & (q <= sm[-1])
    k = np.clip(k, 1, max(sm.size - 1, 1))
    if sm.size == 1:
        return np.where(inside, t[0], np.nan)
    s0, s1, t0, t1 = sm[k - 1], sm[k], t[k - 1], t[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(s1 > s0, (q - s0) / (s1 - s0), 1.0)
    tt = t0 + np.clip(frac, 0.0, 1.0) * (t1 - t0)
    tt = np.where(q == s[0], t[0], tt)
    return np.where(inside, tt, np.nan)


def section_travel_times(bg: pd.DataFrame, s_a: float, s_b: float) -> pd.DataFrame:
    """Travel time of each vehicle over the road section ``[s_a, s_b]``.

    Parameters
    ----------
    bg : DataFrame
        Rows ``t`` [s], ``vehicle_id``, ``s`` [m] (``background.parquet``).
    s_a : float
        Section start along the road [m].
    s_b : float
        Section end [m], ``> s_a``.

    Returns
    -------
    DataFrame
        Index ``vehicle_id``; columns ``t_in``, ``t_out`` [s] (:func:`crossing_times` of
        ``s_a`` and ``s_b``, NaN when not recorded), ``travel_time_s``, ``s_first``,
        ``s_last`` [m] (the recorded range).
    """
    if not s_b > s_a:
        raise ValueError(f"s_b ({s_b!r}) must be greater than s_a ({s_a!r}) [m]")
    rows = {}
    df = bg[["t", "vehicle_id", "s"]].dropna().sort_values(["vehicle_id", "t"], kind="stable")
    for vid, g in df.groupby("vehicle_id", sort=True):
        t, s = g["t"].to_numpy(float), g["s"].to_numpy(float)
        t_in, t_out = crossing_times(t, s, [s_a, s_b])
        rows[str(vid)] = (t_in, t_out, t_out - t_in, s[0], float(np.max(s)))
    out = pd.DataFrame.from_dict(rows, orient="index",
                                 columns=["t_in", "t_out", "travel_time_s", "s_first",
                                          "s_last"])
    out.index.name = "vehicle_id"
    return out


def baseline_comparison(bg_run: pd.DataFrame, bg_base: pd.DataFrame, s_a: float, s_b: float,
                        min_length: float = 50.0) -> pd.DataFrame:
    """Per-vehicle travel times over a common section, formation run vs baseline twin.

    For each vehicle id present in both tables the section ``[s_a, s_b]`` is clipped to
    the part recorded in both runs, ``[max(s_a, s_first), min(s_b, s_last)]`` (the
    formation run records only vehicles near the formation); a vehicle recorded over
    the whole section in both is timed over the whole of it.

    Parameters
    ----------
    bg_run : DataFrame
        Background rows of the formation run (``t``, ``vehicle_id``, ``s``).
    bg_base : DataFrame
        Background rows of the baseline twin (same traffic and seed, no formation).
    s_a : float
        Section start [m].
    s_b : float
        Section end [m].
    min_length : float
        Vehicles whose common part is shorter are left out [m].

    Returns
    -------
    DataFrame
        Index ``vehicle_id``; columns ``s_from``, ``s_to``, ``length_m`` [m],
        ``full_section`` (bool), ``tt_run_s``, ``tt_base_s``, ``delta_s`` (run minus
        baseline) [s], ``v_run_mps``, ``v_base_mps`` (``length_m`` over the travel time)
        [m/s]. Sorted by ``delta_s``, largest first.
    """
    if not s_b > s_a:
        raise ValueError(f"s_b ({s_b!r}) must be greater than s_a ({s_a!r}) [m]")
    cols = ["s_from", "s_to", "length_m", "full_section", "tt_run_s", "tt_base_s", "delta_s",
            "v_run_mps", "v_base_mps"]
    runs = {}
    for name, bg in (("run", bg_run), ("base", bg_base)):
        df = bg[["t", "vehicle_id", "s"]].dropna()
        df = df.assign(vehicle_id=df["vehicle_id"].astype(str)).sort_values(
            ["vehicle_id", "t"], kind="stable")
        runs[name] = {k: (g["t"].to_numpy(float), g["s"].to_numpy(float))
                      for k, g in df.groupby("vehicle_id", sort=False)}
    rows = {}
    for vid in sorted(set(runs["run"]) & set(runs["base"])):
        (tr, sr), (tb, sb_) = runs["run"][vid], runs["base"][vid]
        lo = max(s_a, sr[0], sb_[0])
        hi = min(s_b, float(np.max(sr)), float(np.max(sb_)))
        if not hi - lo >= min_length:
            continue
        a_r, b_r = crossing_times(tr, sr, [lo, hi])
        a_b, b_b = crossing_times(tb, sb_, [lo, hi])
        tt_r, tt_b = b_r - a_r, b_b - a_b
        length = hi - lo
        with np.errstate(divide="ignore", invalid="ignore"):
            rows[vid] = (lo, hi, length, bool(lo == s_a and hi == s_b), tt_r, tt_b,
                         tt_r - tt_b, length / tt_r if tt_r > 0 else np.nan,
                         length / tt_b if tt_b > 0 else np.nan)
    out = pd.DataFrame.from_dict(rows, orient="index", columns=cols)
    out.index.name = "vehicle_id"
    out["full_section"] = out["full_section"].astype(bool)
    return out.sort_values("delta_s", ascending=False, kind="stable")
