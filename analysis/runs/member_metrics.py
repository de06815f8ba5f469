"""Per-member formation metrics: formation error (eq. 2.5) in the virtual-car frame,
settling, IAE, speed and yaw-rate tracking; comfort and limits come from
:mod:`analysis.runs.member_comfort`.

Definitions and sources: ``docs/metrics.md``. Part of :func:`analysis.runs.summary.compute_run`.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import GAP_FACTOR, Member, RunData
from analysis.metrics import formation
from analysis.metrics.signals import contiguous_segments, peak_abs, rms
from analysis.runs.member_columns import MemberColumns, covered_time_s, segment_sum, to_float
from analysis.runs.member_comfort import comfort_metrics, limit_metrics
from analysis.runs.settings import AnalysisSettings

__all__ = ["FORMATION_MEMBER_METRICS"]

FORMATION_MEMBER_METRICS: dict[str, str] = {
    # key: unit
    "offset_dx_m": "m", "offset_dy_m": "m", "offset_frame": "-",
    "n_samples": "-", "n_segments": "-", "t_first_s": "s", "t_last_s": "s",
    "duration_s": "s",
    "e_lon_rms_m": "m", "e_lon_max_m": "m", "e_lat_rms_m": "m", "e_lat_max_m": "m",
    "e_rms_m": "m", "e_max_m": "m", "e_final_m": "m",
    "settling_time_s": "s", "e_rms_settled_m": "m", "e_max_settled_m": "m",
    "e_lon_rms_settled_m": "m", "e_lat_rms_settled_m": "m",
    "iae_lon_m_s": "m s", "iae_lat_m_s": "m s", "iae_m_s": "m s",
    "v_err_rms_mps": "m/s", "yaw_rate_err_rms_radps": "rad/s",
    "a_lon_peak_mps2": "m/s^2", "a_lon_rms_mps2": "m/s^2", "a_lon_p95_mps2": "m/s^2",
    "a_lat_peak_mps2": "m/s^2", "a_lat_rms_mps2": "m/s^2", "a_lat_p95_mps2": "m/s^2",
    "jerk_lon_peak_mps3": "m/s^3", "jerk_lon_rms_mps3": "m/s^3", "jerk_lon_p95_mps3": "m/s^3",
    "jerk_lon_1s_peak_mps3": "m/s^3",
    "jerk_lat_peak_mps3": "m/s^3", "jerk_lat_rms_mps3": "m/s^3", "jerk_lat_p95_mps3": "m/s^3",
    "t_lat_comfortable_s": "s", "t_lat_medium_s": "s", "t_lat_uncomfortable_s": "s",
    "t_lat_beyond_s": "s",
    "t_lon_above_comfort_s": "s", "n_lon_above_comfort": "-",
    "aw_lon_mps2": "m/s^2", "aw_lat_mps2": "m/s^2", "av_mps2": "m/s^2",
    "aw_crest_lon": "-", "aw_crest_lat": "-",
    "aw_crest_over_9_lon": "-", "aw_crest_over_9_lat": "-",
    "mtvv_lon_mps2": "m/s^2", "mtvv_lat_mps2": "m/s^2",
    "vdv_lon_mps175": "m/s^1.75", "vdv_lat_mps175": "m/s^1.75",
    "slip_over_s": "s", "slip_over_n": "-",
    "traction_over_s": "s", "traction_over_n": "-",
    "friction_over_s": "s", "friction_over_n": "-",
    "a_lat_over_s": "s", "a_lat_over_n": "-",
}
"""Per-member formation, comfort and limit metrics with their units."""


def _settling(e: np.ndarray, t: np.ndarray, tol: float) -> float:
    idx = formation.settling_time(e, 1.0, tol=tol)  # fractional sample index
    if not np.isfinite(idx):
        return math.nan
    return float(np.interp(idx, np.arange(t.size), t) - t[0])


def member_metrics(data: RunData, member: Member, vc: pd.DataFrame,
                   st: AnalysisSettings) -> tuple[dict[str, Any], dict[str, str], pd.DataFrame]:
    """Formation, comfort and limit metrics of one member (FORMATION_MEMBER_METRICS), the
    reasons for what is not available, and its derived series (e_norm, jerk_lon, jerk_lat)."""
    traj, dt = data.trajectories, data.dt
    out: dict[str, Any] = {k: None for k in FORMATION_MEMBER_METRICS}
    out.update(offset_dx_m=member.offset[0], offset_dy_m=member.offset[1],
               offset_frame=member.frame)
    g = traj.loc[traj["vehicle_id"] == member.id]
    m = MemberColumns(data, g)
    empty = pd.DataFrame({"t": [], "vehicle_id": [], "e_norm": [], "jerk_lon": [],
                          "jerk_lat": []})
    if g.empty:
        return out, {"all": "no trajectory rows for this member"}, empty
    t = g["t"].to_numpy(dtype=float)
    segs = contiguous_segments(t, dt, GAP_FACTOR) if math.isfinite(dt) else [slice(0, t.size)]
    out.update(n_samples=int(t.size), n_segments=len(segs), t_first_s=float(t[0]),
               t_last_s=float(t[-1]), duration_s=covered_time_s(t, segs))
    if not math.isfinite(dt):
        m.unavailable["rates"] = "sample spacing unknown: time integrals, jerk, ISO not computed"

    e = _formation_error(m, g, vc, t, segs, dt, st, out)
    # --- speed / yaw-rate tracking of the references (eq. 2.6, 2.8) ---------------------
    cols = m.need("speed tracking", "v_ref", "v")
    if cols:
        out["v_err_rms_mps"] = to_float(rms(cols[0] - cols[1]))
    cols = m.need("yaw-rate tracking", "omega_ref", "yaw_rate")
    if cols:
        out["yaw_rate_err_rms_radps"] = to_float(rms(cols[0] - cols[1]))

    jerk_series = comfort_metrics(data, member.id, m, t, segs, dt, st, out)
    limit_metrics(data, m, segs, dt, out)
    sig = pd.DataFrame({"t": t, "vehicle_id": member.id,
                        "e_norm": e if e is not None else np.full(t.size, np.nan),
                        "jerk_lon": jerk_series["lon"], "jerk_lat": jerk_series["lat"]})
    return out, m.unavailable, sig


def _formation_error(m: MemberColumns, g: pd.DataFrame, vc: pd.DataFrame, t: np.ndarray,
                     segs: list[slice], dt: float, st: AnalysisSettings,
                     out: dict[str, Any]) -> np.ndarray | None:
    """Formation error metrics (eq. 2.5) in the virtual-car frame into ``out``; returns the
    error norm per sample [m] (None when not recorded)."""
    # --- formation error (eq. 2.5), resolved in the virtual-car frame -------------------
    e_lon, e_lat = m.col("e_lon"), m.col("e_lat")
    ex, ey = m.col("ex"), m.col("ey")
    if e_lon is None or e_lat is None:
        lost = m.why("e_lon" if e_lon is None else "e_lat")
        e_lon = e_lat = None
        if ex is not None and ey is not None:
            head = (g[["t"]].merge(vc[["t", "heading"]], on="t", how="left")["heading"]
                    .to_numpy(dtype=float) if not vc.empty else np.full(t.size, np.nan))
            if np.isfinite(head).any():
                c, s = np.cos(head), np.sin(head)
                e_lon, e_lat = c * ex + s * ey, -s * ex + c * ey
                m.unavailable["e_lon/e_lat"] = (f"{lost}; recomputed from ex, ey and the "
                                                "virtual-car heading")
            else:
                m.unavailable["e_lon/e_lat"] = (f"{lost}; no virtual-car heading to resolve "
                                                "ex, ey: only the norm is reported")
        else:
            m.need("formation error", "e_lon", "e_lat", "ex", "ey")
    if e_lon is not None:
        e = formation.error_norm(e_lon, e_lat)
    elif ex is not None and ey is not None:
        e = formation.error_norm(ex, ey)
    else:
        e = None
    if e is not None:
        for key, x in (("e_lon", e_lon), ("e_lat", e_lat), ("e", e)):
            if x is not None:
                out[f"{key}_rms_m"] = to_float(rms(x))
                out[f"{key}_max_m"] = to_float(peak_abs(x))
        fin = np.nonzero(np.isfinite(e))[0]
        out["e_final_m"] = float(e[fin[-1]]) if fin.size else None
        ts = _settling(e, t, st.settle_tol_m)
        out["settling_time_s"] = ts
        if math.isfinite(ts):
            after = (t - t[0]) >= ts - 1e-12
            out["e_rms_settled_m"] = to_float(rms(e[after]))
            out["e_max_settled_m"] = to_float(peak_abs(e[after]))
            if e_lon is not None:
                out["e_lon_rms_settled_m"] = to_float(rms(e_lon[after]))
                out["e_lat_rms_settled_m"] = to_float(rms(e_lat[after]))
        else:
            m.unavailable["settled"] = (f"never settles within {st.settle_tol_m:g} m "
                                        "(last sample outside the band)")
        if math.isfinite(dt):
            for key, x in (("iae_lon_m_s", e_lon), ("iae_lat_m_s", e_lat), ("iae_m_s", e)):
                if x is not None:
                    out[key] = segment_sum(lambda a: formation.iae(np.nan_to_num(a), dt), segs, x)

    return e
