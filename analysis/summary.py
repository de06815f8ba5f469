"""Per-run computation: from a loaded :class:`~analysis.load.RunData` to metric tables.

This layer knows the recorded columns and handles damage (missing columns, gaps, NaN
signals); the metric definitions themselves are the pure functions of
:mod:`analysis.formation`, :mod:`analysis.comfort`, :mod:`analysis.iso2631` and
:mod:`analysis.limits`. No file is written here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from analysis import comfort, formation, iso2631, limits, traffic
from analysis.energy import ENERGY_MEMBER_METRICS, ENERGY_RUN_METRICS, EnergyAnalysis, compute_energy
from analysis.load import GAP_FACTOR, Issue, Member, RunData
from analysis.comm import COMM_MEMBER_METRICS, comm_analysis
from analysis.traffic_run import (TRAFFIC_MEMBER_METRICS, BaselineData, TrafficAnalysis,
                                  compute_traffic)
from analysis.settings import DEFAULT_SETTINGS, AnalysisSettings, settings_dict
from analysis.signals import (contiguous_segments, peak_abs, percentile_abs, rms,
                              trapezoid_integral)
from formation_traci.record.columns import VIRTUAL_CAR_ID

__all__ = [
    "AnalysisSettings",
    "DEFAULT_SETTINGS",
    "FORMATION_MEMBER_METRICS",
    "MEMBER_METRICS",
    "RUN_METRICS",
    "KEY_METRICS",
    "RunAnalysis",
    "compute_run",
    "settings_dict",
]


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
    "slip_over_s": "s", "slip_over_n": "-",
    "traction_over_s": "s", "traction_over_n": "-",
    "friction_over_s": "s", "friction_over_n": "-",
    "a_lat_over_s": "s", "a_lat_over_n": "-",
}
"""Per-member formation, comfort and limit metrics with their units."""

MEMBER_METRICS: dict[str, str] = {**FORMATION_MEMBER_METRICS, **ENERGY_MEMBER_METRICS,
                                  **COMM_MEMBER_METRICS, **TRAFFIC_MEMBER_METRICS}
"""Per-member metrics, in output order, with their units (see docs/metrics.md): the
formation metrics, then energy (:data:`analysis.energy.ENERGY_MEMBER_METRICS`), the
communication ones (:data:`analysis.comm.COMM_MEMBER_METRICS`), then the traffic ones
(:data:`analysis.traffic_run.TRAFFIC_MEMBER_METRICS`)."""

RUN_METRICS: dict[str, str] = {
    "status": "-", "reason": "-", "model": "-", "mu": "-", "t_end_s": "s",
    "record_step_s": "s", "dt_s": "s", "sample_rate_hz": "Hz",
    "t_first_s": "s", "t_last_s": "s", "duration_s": "s",
    "n_members": "-", "n_members_with_data": "-",
    "shape_error_rms_m": "m", "shape_error_max_m": "m", "shape_error_final_m": "m",
    "shape_source": "-", "shape_members": "-",
    "string_stable": "-", "string_peak_ratio_max": "-", "string_rms_ratio_max": "-",
    "iso2631_band_hz": "Hz", "iso2631_full_band": "-", "iso2631_note": "-",
    **ENERGY_RUN_METRICS,
}
"""Run-level metrics with their units."""

KEY_METRICS: tuple[str, ...] = (
    "e_rms_m", "e_max_m", "settling_time_s", "e_rms_settled_m", "iae_m_s",
    "v_err_rms_mps", "yaw_rate_err_rms_radps",
    "a_lat_peak_mps2", "a_lon_peak_mps2", "jerk_lat_peak_mps3", "jerk_lon_peak_mps3",
    "aw_lat_mps2", "av_mps2", "t_lat_medium_s", "t_lat_uncomfortable_s", "t_lat_beyond_s",
    "t_lon_above_comfort_s", "slip_over_s", "traction_over_s", "friction_over_s",
    "a_lat_over_s",
)
"""Per-member metrics summarised per run as the worst member (largest value)."""

_TIRE_COLUMNS = ("slip_front", "slip_rear", "traction_force", "traction_force_max", "steer",
                 "steer_rate", "beta")


@dataclass(frozen=True)
class RunAnalysis:
    """Everything computed for one run (no files written)."""

    data: RunData
    settings: AnalysisSettings
    run: dict[str, Any]  # RUN_METRICS plus "worst" (KEY_METRICS, max over members)
    members: pd.DataFrame  # one row per member, index "id", columns MEMBER_METRICS
    string_stability: pd.DataFrame  # one row per (leader, follower) pair of a column
    unavailable: dict[str, dict[str, str]]  # member id -> metric group -> reason
    signals: pd.DataFrame  # derived time series: t, vehicle_id, e_norm, jerk_lon, jerk_lat
    shape: pd.DataFrame  # t, shape_error [m]
    issues: tuple[Issue, ...]
    traffic: TrafficAnalysis | None = None  # traffic interaction (None if not computed)
    energy: EnergyAnalysis | None = None  # traction energy per member (analysis/energy.py)
    comm_age: pd.DataFrame | None = None  # error and comfort per leader-age bin (analysis/comm.py)


class _Member:
    """Column access for one member with reasons for what is not available."""

    def __init__(self, data: RunData, g: pd.DataFrame):
        self.data, self.g = data, g
        self.unavailable: dict[str, str] = {}

    def col(self, name: str) -> np.ndarray | None:
        if name in self.data.missing_columns:
            return None
        x = self.g[name].to_numpy(dtype=float)
        return x if np.isfinite(x).any() else None

    def why(self, name: str) -> str:
        if name in self.data.missing_columns:
            return f"column '{name}' missing from the record"
        if name in _TIRE_COLUMNS and self.data.meta.get("model") == "kinematic":
            return f"'{name}' is all NaN (the kinematic model has no tires)"
        return f"'{name}' is all NaN"

    def need(self, group: str, *names: str) -> list[np.ndarray] | None:
        cols = [self.col(n) for n in names]
        missing = [n for n, c in zip(names, cols) if c is None]
        if missing:
            self.unavailable[group] = "; ".join(self.why(n) for n in missing)
            return None
        return cols


def _f(x: Any) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return math.nan
    return x


def _covered(t: np.ndarray, segs: list[slice]) -> float:
    """Recorded time without the gaps: sum of the segment spans [s]."""
    return float(sum(t[s.stop - 1] - t[s.start] for s in segs))


def _seg_sum(fn, segs: list[slice], *arrays: np.ndarray) -> float:
    return float(sum(fn(*(a[s] for a in arrays)) for s in segs))


def _per_segment(fn, segs: list[slice], a: np.ndarray, n_min: int) -> tuple[np.ndarray, int]:
    out = np.full(a.shape, np.nan)
    skipped = 0
    for s in segs:
        if s.stop - s.start >= n_min:
            out[s] = fn(a[s])
        else:
            skipped += 1
    return out, skipped


def _settling(e: np.ndarray, t: np.ndarray, tol: float) -> float:
    idx = formation.settling_time(e, 1.0, tol=tol)  # fractional sample index
    if not np.isfinite(idx):
        return math.nan
    return float(np.interp(idx, np.arange(t.size), t) - t[0])


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
    reason = ok[0][1].reason
    if len(ok) < len(results):
        reason = ((reason + "; ") if reason else "") + (
            f"{len(results) - len(ok)} of {len(results)} record segments too short or "
            "invalid, left out")
    return iso2631.WeightedRMS(value, crest, ok[0][1].band_hz, ok[0][1].full_band, reason)


def _member_metrics(data: RunData, member: Member, vc: pd.DataFrame,
                    st: AnalysisSettings) -> tuple[dict[str, Any], dict[str, str], pd.DataFrame]:
    traj, dt = data.trajectories, data.dt
    out: dict[str, Any] = {k: None for k in FORMATION_MEMBER_METRICS}
    out.update(offset_dx_m=member.offset[0], offset_dy_m=member.offset[1],
               offset_frame=member.frame)
    g = traj.loc[traj["vehicle_id"] == member.id]
    m = _Member(data, g)
    empty = pd.DataFrame({"t": [], "vehicle_id": [], "e_norm": [], "jerk_lon": [],
                          "jerk_lat": []})
    if g.empty:
        return out, {"all": "no trajectory rows for this member"}, empty
    t = g["t"].to_numpy(dtype=float)
    segs = contiguous_segments(t, dt, GAP_FACTOR) if math.isfinite(dt) else [slice(0, t.size)]
    out.update(n_samples=int(t.size), n_segments=len(segs), t_first_s=float(t[0]),
               t_last_s=float(t[-1]), duration_s=_covered(t, segs))
    if not math.isfinite(dt):
        m.unavailable["rates"] = "sample spacing unknown: time integrals, jerk, ISO not computed"

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
                out[f"{key}_rms_m"] = _f(rms(x))
                out[f"{key}_max_m"] = _f(peak_abs(x))
        fin = np.nonzero(np.isfinite(e))[0]
        out["e_final_m"] = float(e[fin[-1]]) if fin.size else None
        ts = _settling(e, t, st.settle_tol_m)
        out["settling_time_s"] = ts
        if math.isfinite(ts):
            after = (t - t[0]) >= ts - 1e-12
            out["e_rms_settled_m"] = _f(rms(e[after]))
            out["e_max_settled_m"] = _f(peak_abs(e[after]))
            if e_lon is not None:
                out["e_lon_rms_settled_m"] = _f(rms(e_lon[after]))
                out["e_lat_rms_settled_m"] = _f(rms(e_lat[after]))
        else:
            m.unavailable["settled"] = (f"never settles within {st.settle_tol_m:g} m "
                                        "(last sample outside the band)")
        if math.isfinite(dt):
            for key, x in (("iae_lon_m_s", e_lon), ("iae_lat_m_s", e_lat), ("iae_m_s", e)):
                if x is not None:
                    out[key] = _seg_sum(lambda a: formation.iae(np.nan_to_num(a), dt), segs, x)

    # --- speed / yaw-rate tracking of the references (eq. 2.6, 2.8) ---------------------
    cols = m.need("speed tracking", "v_ref", "v")
    if cols:
        out["v_err_rms_mps"] = _f(rms(cols[0] - cols[1]))
    cols = m.need("yaw-rate tracking", "omega_ref", "yaw_rate")
    if cols:
        out["yaw_rate_err_rms_radps"] = _f(rms(cols[0] - cols[1]))

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
        out[f"a_{axis_name}_peak_mps2"] = _f(peak_abs(a))
        out[f"a_{axis_name}_rms_mps2"] = _f(rms(a))
        out[f"a_{axis_name}_p95_mps2"] = _f(percentile_abs(a, 95.0))
        if n_win is None:
            continue
        j, skipped = _per_segment(
            lambda x: comfort.jerk(x, dt, st.jerk_window_s, st.jerk_polyorder), segs, a, n_win)
        jerk_series[axis_name] = j
        if skipped == len(segs):
            m.unavailable[f"jerk {axis_name}"] = (f"record shorter than the {n_win}-sample "
                                                  "Savitzky-Golay window")
        else:
            if skipped:
                m.unavailable[f"jerk {axis_name}"] = (f"{skipped} segment(s) shorter than the "
                                                      "window left out")
            out[f"jerk_{axis_name}_peak_mps3"] = _f(peak_abs(j))
            out[f"jerk_{axis_name}_rms_mps3"] = _f(rms(j))
            out[f"jerk_{axis_name}_p95_mps3"] = _f(percentile_abs(j, 95.0))
        if axis_name == "lon" and math.isfinite(dt):
            out["jerk_lon_1s_peak_mps3"] = _jerk_1s_peak(data, member.id, t, a, segs, dt)
        hr = _control_rate(data, member.id, f"a_{axis_name}")
        w = _weighted(*hr) if hr is not None else _weighted(a, segs, dt)
        aw[axis_name] = w
        out[f"aw_{axis_name}_mps2"] = _f(w.value)
        out[f"aw_crest_{axis_name}"] = _f(w.crest_factor)
        if w.reason and not np.isfinite(w.value) and not w.reason.startswith("sample rate"):
            m.unavailable[f"ISO 2631 {axis_name}"] = w.reason
    if "lon" in aw and "lat" in aw:
        out["av_mps2"] = _f(iso2631.vibration_total_value(aw["lon"].value, aw["lat"].value))

    def _limit(prefix: str, mask: np.ndarray) -> None:
        out[f"{prefix}_s"] = _f(limits.exceedance(mask, dt).time_s)
        out[f"{prefix}_n"] = _seg_sum(lambda x: limits.exceedance(x, dt).episodes, segs, mask)

    a_lat, a_lon = m.col("a_lat"), m.col("a_lon")
    if a_lat is not None and math.isfinite(dt):
        bt = comfort.band_times(a_lat, dt)
        for name, v in zip(comfort.LAT_BAND_NAMES, bt):
            out[f"t_lat_{name}_s"] = float(v)
        _limit("a_lat_over", limits.lat_acc_mask(a_lat))
    if a_lon is not None and math.isfinite(dt):
        mask = np.abs(a_lon) > comfort.LON_ACC_COMFORT
        out["t_lon_above_comfort_s"] = _f(limits.exceedance(mask, dt).time_s)
        out["n_lon_above_comfort"] = _seg_sum(lambda x: limits.exceedance(x, dt).episodes,
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
            mu = _f(data.meta.get("mu"))
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
    sig = pd.DataFrame({"t": t, "vehicle_id": member.id,
                        "e_norm": e if e is not None else np.full(t.size, np.nan),
                        "jerk_lon": jerk_series["lon"], "jerk_lat": jerk_series["lat"]})
    return out, m.unavailable, sig


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
    return _f(peak_abs(j)) if np.isfinite(j).any() else None


def _shape(data: RunData, members: list[Member]) -> tuple[dict[str, Any], pd.DataFrame, list[Issue]]:
    traj = data.trajectories
    ids_data = set(traj["vehicle_id"])
    use = [m for m in members if m.id in ids_data]
    res: dict[str, Any] = {"shape_error_rms_m": None, "shape_error_max_m": None,
                           "shape_error_final_m": None, "shape_source": None,
                           "shape_members": [m.id for m in use]}
    empty = pd.DataFrame({"t": [], "shape_error": []})
    if len(use) < 2:
        return res, empty, [Issue("info", "not_applicable", "shape_error",
                                  "fewer than two members with data: no shape error")]
    if {"x", "y"} & data.missing_columns:
        return res, empty, [Issue("warning", "not_computed", "shape_error",
                                  "x or y column missing")]
    ids = [m.id for m in use]
    sub = traj.loc[traj["vehicle_id"].isin(ids)]
    px = sub.pivot(index="t", columns="vehicle_id", values="x")[ids]
    py = sub.pivot(index="t", columns="vehicle_id", values="y")[ids]
    ok = px.notna().all(axis=1) & py.notna().all(axis=1)
    issues: list[Issue] = []
    offsets = np.array([m.offset for m in use], dtype=float)
    if np.isfinite(offsets).all():
        desired = formation.desired_pair_distances(offsets)
        frames = {m.frame for m in use}
        res["shape_source"] = "offsets (" + "/".join(sorted(frames)) + " frame)"
        if "road" in frames:
            issues.append(Issue("info", "approximation", "shape_error",
                                "road-frame offsets: desired distances taken as a rigid "
                                "shape, exact on straight roads only"))
    else:
        if {"x_des", "y_des"} & data.missing_columns:
            return res, empty, [Issue("warning", "not_computed", "shape_error",
                                      "offsets unknown and x_des/y_des missing")]
        qx = sub.pivot(index="t", columns="vehicle_id", values="x_des")[ids]
        qy = sub.pivot(index="t", columns="vehicle_id", values="y_des")[ids]
        ok &= qx.notna().all(axis=1) & qy.notna().all(axis=1)
        desired = formation.pair_distances(qx[ok].to_numpy().T, qy[ok].to_numpy().T)
        res["shape_source"] = "desired positions x_des, y_des"
    if not ok.any():
        return res, empty, [Issue("warning", "not_computed", "shape_error",
                                  "no instant with every member's position")]
    eps = formation.shape_error(px[ok].to_numpy().T, py[ok].to_numpy().T, desired)
    res["shape_error_rms_m"] = _f(rms(eps))
    res["shape_error_max_m"] = _f(peak_abs(eps))
    res["shape_error_final_m"] = float(eps[-1])
    if (~ok).any():
        issues.append(Issue("info", "partial", "shape_error",
                            f"{int((~ok).sum())} instants without every member left out"))
    return res, pd.DataFrame({"t": px.index[ok].to_numpy(), "shape_error": eps}), issues


def _string_stability(members: list[Member], signals: pd.DataFrame,
                      st: AnalysisSettings) -> pd.DataFrame:
    cols = ["column", "dy_m", "position", "leader", "follower", "peak_ratio", "rms_ratio",
            "amplifies"]
    offsets = {m.id: m.offset for m in members if np.isfinite(m.offset).all()}
    rows = []
    for k, column in enumerate(formation.formation_columns(offsets, st.column_dy_tol_m)):
        piv = signals.loc[signals["vehicle_id"].isin(column)].pivot(
            index="t", columns="vehicle_id", values="e_norm")
        present = [c for c in column if c in piv.columns]
        if len(present) < 2:
            continue
        e = piv[present].dropna().to_numpy().T
        if e.shape[1] == 0:
            continue
        r = formation.string_stability_ratios(e)
        for i in range(len(present) - 1):
            rows.append({"column": k, "dy_m": float(offsets[present[0]][1]), "position": i + 1,
                         "leader": present[i], "follower": present[i + 1],
                         "peak_ratio": float(r.peak[i]), "rms_ratio": float(r.rms[i]),
                         "amplifies": bool(r.peak[i] > 1.0)})
    return pd.DataFrame(rows, columns=cols)


def _iso2631_band(run: dict[str, Any], fs: float, dt: float) -> list[Issue]:
    """Fill run's iso2631_* entries for sample rate fs [Hz]; the issue when ISO 2631
    weighting is unavailable at that rate."""
    f_valid = iso2631.valid_upper_frequency(fs)
    run["iso2631_band_hz"] = [iso2631.ISO_FREQ_RANGE_HZ[0],
                              min(iso2631.ISO_FREQ_RANGE_HZ[1], f_valid)]
    run["iso2631_full_band"] = bool(f_valid >= iso2631.ISO_FREQ_RANGE_HZ[1])
    probe = iso2631.weighted_rms(np.zeros(int(iso2631.MIN_DURATION_S * fs) + 1), dt)
    run["iso2631_note"] = probe.reason or "full 0.5-80 Hz band"
    if not np.isfinite(probe.value):
        return [Issue("warning", "iso2631_unavailable", "aw_*", probe.reason)]
    return []


def _worst(mdf: pd.DataFrame) -> dict[str, float | None]:
    """Largest value over the members of every KEY_METRICS column (None: no data)."""
    worst = {}
    for k in KEY_METRICS:
        col = pd.to_numeric(mdf[k], errors="coerce")
        worst[k] = _f(col.max()) if col.notna().any() else None
    return worst


def compute_run(data: RunData, settings: AnalysisSettings = DEFAULT_SETTINGS,
                baseline: BaselineData | None = None) -> RunAnalysis:
    """Compute every metric of a loaded run.

    Parameters
    ----------
    data : RunData
        Output of :func:`analysis.load.load_run`.
    settings : AnalysisSettings
        Analysis choices; default :data:`DEFAULT_SETTINGS`.
    baseline : BaselineData, optional
        Twin run without the formation (:func:`analysis.traffic_run.load_baseline`) for
        the traffic comparison.

    Returns
    -------
    RunAnalysis
        Run-level metrics, the per-member table, string-stability pairs, per-member
        reasons for metrics left out, derived time series and the issues of loading plus
        those found while computing.
    """
    traj, meta, dt = data.trajectories, data.meta, data.dt
    issues = list(data.issues)
    vc = traj.loc[traj["vehicle_id"] == VIRTUAL_CAR_ID]
    members = list(data.members)
    rows, unavailable, sigs = [], {}, []
    for mem in members:
        out, why, sig = _member_metrics(data, mem, vc, settings)
        rows.append({"id": mem.id, **out})
        if why:
            unavailable[mem.id] = why
        sigs.append(sig)
    mdf = pd.DataFrame(rows, columns=["id", *FORMATION_MEMBER_METRICS]).set_index("id")
    tra = compute_traffic(data, settings, baseline)
    issues += list(tra.issues)
    energy = compute_energy(data)
    signals = pd.concat([s for s in sigs if len(s)], ignore_index=True) if any(
        len(s) for s in sigs) else pd.DataFrame(columns=["t", "vehicle_id", "e_norm",
                                                         "jerk_lon", "jerk_lat"])
    comm_members, comm_age = comm_analysis(traj, signals, [m.id for m in members])
    mdf = mdf.join(energy.members, how="left").join(tra.members, how="left") \
        .join(comm_members, how="left")[list(MEMBER_METRICS)]
    shape_res, shape_df, shape_issues = _shape(data, members)
    issues += shape_issues
    ss = _string_stability(members, signals, settings)

    t_all = traj["t"].to_numpy(dtype=float)
    fs = 1.0 / dt if math.isfinite(dt) else math.nan
    run: dict[str, Any] = {k: None for k in RUN_METRICS}
    run.update(
        status=meta.get("status"), reason=meta.get("reason"), model=meta.get("model"),
        mu=meta.get("mu"), t_end_s=meta.get("t_end"), record_step_s=meta.get("record_step"),
        dt_s=dt if math.isfinite(dt) else None, sample_rate_hz=fs if math.isfinite(fs) else None,
        t_first_s=float(t_all.min()), t_last_s=float(t_all.max()),
        duration_s=_covered(np.unique(t_all), contiguous_segments(np.unique(t_all), dt, GAP_FACTOR)
                            if math.isfinite(dt) else [slice(0, np.unique(t_all).size)]),
        n_members=len(members), n_members_with_data=int(mdf["n_samples"].notna().sum()),
        **shape_res, **energy.run,
    )
    if len(ss):
        run.update(string_stable=bool(not ss["amplifies"].any()),
                   string_peak_ratio_max=_f(ss["peak_ratio"].max()),
                   string_rms_ratio_max=_f(ss["rms_ratio"].max()))
    dt_iso = control_rate_dt(data) if math.isfinite(control_rate_dt(data)) else dt
    if math.isfinite(dt_iso):  # ISO 2631 from comfort.parquet (control rate) when recorded
        issues += _iso2631_band(run, 1.0 / dt_iso, dt_iso)
    run["worst"] = _worst(mdf)
    return RunAnalysis(data=data, settings=settings, run=run, members=mdf,
                       string_stability=ss, unavailable=unavailable, signals=signals,
                       shape=shape_df, issues=tuple(issues), traffic=tra, energy=energy,
                       comm_age=comm_age)
