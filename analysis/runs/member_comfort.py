"""Per-member comfort and limit metrics: accelerations, jerk (Savitzky-Golay and the
1 s mean of ISO 15622), ISO 2631-1 weighted r.m.s. (from ``comfort.parquet`` at the
control rate when recorded), lateral comfort bands and the limits of section 3.3.1.

Definitions and sources: ``docs/metrics.md``. Part of :func:`analysis.runs.summary.compute_run`.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from analysis.load.run_data import GAP_FACTOR, RunData
from analysis.metrics import comfort, iso2631, limits
from analysis.metrics.signals import contiguous_segments, peak_abs, percentile_abs, rms
from analysis.runs.member_columns import MemberColumns, per_segment, segment_sum, to_float
from analysis.runs.settings import AnalysisSettings
from run_contract.columns import VIRTUAL_CAR_ID


def control_rate_dt(data: RunData) -> float:
    """Sample spacing of ``comfort.parquet`` [s] (the control period), NaN without it."""
    cf = data.tables.get("comfort")
    if cf is None or not len(cf) or "t" not in cf.columns:
        return math.nan
    t = np.unique(cf["t"].to_numpy(dtype=float))
    return float(np.median(np.diff(t))) if t.size > 1 else math.nan


def _control_rate(data: RunData, member_id: str, column: str):
    """(signal, segments, dt) of a member from ``comfort.parquet``, or None without it."""
    dt = control_rate_dt(data)
    cf = data.tables.get("comfort")
    if not math.isfinite(dt) or column not in cf.columns:
        return None
    g = cf.loc[cf["vehicle_id"].astype(str) == member_id].sort_values("t", kind="stable")
    if len(g) < 2:
        return None
    t = g["t"].to_numpy(dtype=float)
    return g[column].to_numpy(dtype=float), contiguous_segments(t, dt, GAP_FACTOR), dt


def _weighted(a: np.ndarray, segs: list[slice], dt: float) -> iso2631.WeightedRMS:
    results = [(s.stop - s.start, iso2631.weighted_rms(a[s], dt)) for s in segs]
    ok = [(n, r) for n, r in results if np.isfinite(r.value)]
    if not ok:
        longest = max(results, key=lambda nr: nr[0])[1]
        return longest
    n_tot = sum(n for n, _ in ok)
    value = math.sqrt(sum(n * float(r.value) ** 2 for n, r in ok) / n_tot)
    crest = max(float(r.crest_factor) for _, r in ok)
    mtvv = max(float(r.mtvv) for _, r in ok)  # the largest running r.m.s. of any segment
    vdv = sum(float(r.vdv) ** 4 for _, r in ok) ** 0.25  # doses add (ISO 2631-1 6.3.2)
    reason = ok[0][1].reason
    if len(ok) < len(results):
        reason = ((reason + "; ") if reason else "") + (
            f"{len(results) - len(ok)} of {len(results)} record segments too short or "
            "invalid, left out")
    return iso2631.WeightedRMS(value, crest, ok[0][1].band_hz, ok[0][1].full_band, reason,
                               mtvv, vdv)


def _jerk_1s_peak(data: RunData, member_id: str, t: np.ndarray, a: np.ndarray, segs,
                  dt: float) -> float | None:
    """Peak |jerk averaged over 1 s| (ISO 15622) [m/s^3] outside the emergency brakes the run
    recorded for this member or the virtual car (``emergency_brake`` .. ``emergency_end``)."""
    ev = data.tables.get("events")
    starts, ends = np.empty(0), np.empty(0)
    if ev is not None and len(ev) and {"kind", "vehicle_id", "t"} <= set(ev.columns):
        who = ev["vehicle_id"].astype(str).isin([member_id, VIRTUAL_CAR_ID])
        kind = ev["kind"].astype(str)
        starts = ev.loc[who & (kind == "emergency_brake"), "t"].to_numpy(dtype=float)
        ends = ev.loc[who & (kind == "emergency_end"), "t"].to_numpy(dtype=float)
    j = np.concatenate([comfort.jerk_window_mean(a[s], dt) for s in segs]) if segs else np.empty(0)
    j[comfort.emergency_mask(t, starts, ends)] = np.nan
    return to_float(peak_abs(j)) if np.isfinite(j).any() else None


def comfort_metrics(data: RunData, member_id: str, m: MemberColumns, t: np.ndarray,
                    segs: list[slice], dt: float, st: AnalysisSettings,
                    out: dict[str, Any]) -> dict[str, np.ndarray]:
    """Acceleration, jerk and ISO 2631 metrics of one member into ``out``; returns the jerk
    series per axis (``lon``, ``lat``) [m/s^3], NaN where not computed."""
    # --- comfort -------------------------------------------------------------------------
    jerk_series = {"lon": np.full(t.size, np.nan), "lat": np.full(t.size, np.nan)}
    n_win = comfort.savgol_window_samples(st.jerk_window_s, dt, st.jerk_polyorder) \
        if math.isfinite(dt) else None
    aw = {}
    for axis_name in ("lon", "lat"):
        a = m.col(f"a_{axis_name}")
        if a is None:
            m.unavailable[f"comfort {axis_name}"] = m.why(f"a_{axis_name}")
            continue
        out[f"a_{axis_name}_peak_mps2"] = to_float(peak_abs(a))
        out[f"a_{axis_name}_rms_mps2"] = to_float(rms(a))
        out[f"a_{axis_name}_p95_mps2"] = to_float(percentile_abs(a, 95.0))
        if n_win is None:
            continue
        j, skipped = per_segment(
            lambda x: comfort.jerk(x, dt, st.jerk_window_s, st.jerk_polyorder), segs, a, n_win)
        jerk_series[axis_name] = j
        if skipped == len(segs):
            m.unavailable[f"jerk {axis_name}"] = (f"record shorter than the {n_win}-sample "
                                                  "Savitzky-Golay window")
        else:
            if skipped:
                m.unavailable[f"jerk {axis_name}"] = (f"{skipped} segment(s) shorter than the "
                                                      "window left out")
            out[f"jerk_{axis_name}_peak_mps3"] = to_float(peak_abs(j))
            out[f"jerk_{axis_name}_rms_mps3"] = to_float(rms(j))
            out[f"jerk_{axis_name}_p95_mps3"] = to_float(percentile_abs(j, 95.0))
        if axis_name == "lon" and math.isfinite(dt):
            out["jerk_lon_1s_peak_mps3"] = _jerk_1s_peak(data, member_id, t, a, segs, dt)
        hr = _control_rate(data, member_id, f"a_{axis_name}")
        w = _weighted(*hr) if hr is not None else _weighted(a, segs, dt)
        aw[axis_name] = w
        out[f"aw_{axis_name}_mps2"] = to_float(w.value)
        out[f"aw_crest_{axis_name}"] = to_float(w.crest_factor)
        high = bool(np.isfinite(w.crest_factor) and w.crest_factor > iso2631.CREST_FACTOR_LIMIT)
        out[f"aw_crest_over_9_{axis_name}"] = high if np.isfinite(w.crest_factor) else None
        out[f"mtvv_{axis_name}_mps2"] = to_float(w.mtvv)
        out[f"vdv_{axis_name}_mps175"] = to_float(w.vdv)
        if w.reason and not np.isfinite(w.value) and not w.reason.startswith("sample rate"):
            m.unavailable[f"ISO 2631 {axis_name}"] = w.reason
    if "lon" in aw and "lat" in aw:
        out["av_mps2"] = to_float(iso2631.vibration_total_value(aw["lon"].value, aw["lat"].value))

    return jerk_series


def limit_metrics(data: RunData, m: MemberColumns, segs: list[slice], dt: float,
                  out: dict[str, Any]) -> None:
    """Lateral comfort bands, longitudinal comfort and the limits of section 3.3.1 of one
    member (time above and episodes) into ``out``."""
    def _limit(prefix: str, mask: np.ndarray) -> None:
        out[f"{prefix}_s"] = to_float(limits.exceedance(mask, dt).time_s)
        out[f"{prefix}_n"] = segment_sum(lambda x: limits.exceedance(x, dt).episodes, segs, mask)

    a_lat, a_lon = m.col("a_lat"), m.col("a_lon")
    if a_lat is not None and math.isfinite(dt):
        bt = comfort.band_times(a_lat, dt)
        for name, v in zip(comfort.LAT_BAND_NAMES, bt):
            out[f"t_lat_{name}_s"] = float(v)
        _limit("a_lat_over", limits.lat_acc_mask(a_lat))
    if a_lon is not None and math.isfinite(dt):
        mask = np.abs(a_lon) > comfort.LON_ACC_COMFORT
        out["t_lon_above_comfort_s"] = to_float(limits.exceedance(mask, dt).time_s)
        out["n_lon_above_comfort"] = segment_sum(lambda x: limits.exceedance(x, dt).episodes,
                                              segs, mask)

    # --- limits of section 3.3.1 ---------------------------------------------------------
    if math.isfinite(dt):
        cols = m.need("slip limit", "slip_front", "slip_rear")
        if cols:
            _limit("slip_over", limits.slip_mask(*cols))
        cols = m.need("traction limit", "traction_force", "traction_force_max")
        if cols:
            _limit("traction_over", limits.traction_mask(*cols))
        usage = m.col("friction_usage")
        if usage is None and a_lon is not None and a_lat is not None:
            mu = to_float(data.meta.get("mu"))
            if math.isfinite(mu) and mu > 0:
                usage = limits.friction_usage(a_lon, a_lat, mu)
                m.unavailable["friction usage"] = (m.why("friction_usage") + "; recomputed "
                                                   f"from a_lon, a_lat and mu = {mu:g}")
        if usage is not None:
            _limit("friction_over", limits.friction_mask(usage))
        elif "friction usage" not in m.unavailable:
            m.unavailable["friction limit"] = m.why("friction_usage") + " and mu unknown"

    for k in ("n_lon_above_comfort", "slip_over_n", "traction_over_n", "friction_over_n",
              "a_lat_over_n"):
        if out[k] is not None:
            out[k] = int(out[k])
