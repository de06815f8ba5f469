"""Per-run computation: from a loaded :class:`~analysis.load.run_data.RunData` to metric tables.

This layer knows the recorded columns and handles damage (missing columns, gaps, NaN
signals); the metric definitions themselves are the pure functions of
:mod:`analysis.metrics.formation`, :mod:`analysis.metrics.comfort`, :mod:`analysis.metrics.iso2631`
and :mod:`analysis.metrics.limits`. No file is written here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from run_contract.columns import INCIDENT_KEYS

from analysis.load.run_data import GAP_FACTOR, Issue, Member, RunData
from analysis.metrics import formation, iso2631
from analysis.metrics.comm import COMM_MEMBER_METRICS, comm_analysis
from analysis.metrics.platoon import formation_amplification
from analysis.metrics.signals import contiguous_segments, peak_abs, rms
from analysis.runs.energy import (ENERGY_MEMBER_METRICS, ENERGY_RUN_METRICS, EnergyAnalysis,
                                  compute_energy)
from analysis.runs.member_columns import covered_time_s, to_float
from analysis.runs.member_comfort import control_rate_dt
from analysis.runs.member_metrics import FORMATION_MEMBER_METRICS, member_metrics
from analysis.runs.settings import DEFAULT_SETTINGS, AnalysisSettings, settings_dict
from analysis.runs.traffic_run import (TRAFFIC_MEMBER_METRICS, BaselineData, TrafficAnalysis,
                                       compute_traffic)
from run_contract.columns import VIRTUAL_CAR_ID

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


MEMBER_METRICS: dict[str, str] = {**FORMATION_MEMBER_METRICS, **ENERGY_MEMBER_METRICS,
                                  **COMM_MEMBER_METRICS, **TRAFFIC_MEMBER_METRICS}
"""Per-member metrics, in output order, with their units (see docs/metrics.md): the
formation metrics, then energy (:data:`analysis.runs.energy.ENERGY_MEMBER_METRICS`), the
communication ones (:data:`analysis.metrics.comm.COMM_MEMBER_METRICS`), then the traffic ones
(:data:`analysis.runs.traffic_run.TRAFFIC_MEMBER_METRICS`)."""

RUN_METRICS: dict[str, str] = {
    "status": "-", "reason": "-", "model": "-", "mu": "-", "t_end_s": "s",
    **{k: "-" for k in INCIDENT_KEYS},
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
    energy: EnergyAnalysis | None = None  # traction energy per member (analysis/runs/energy.py)
    # error and comfort per leader-age bin (analysis/metrics/comm.py)
    comm_age: pd.DataFrame | None = None
    # per formation: string_amplification of its columns (analysis/metrics/platoon.py)
    formations: tuple = ()
    # several formations: analysis.runs.fleet.FleetAnalysis (each one's and the fleet's)
    fleet: Any = None


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
    res["shape_error_rms_m"] = to_float(rms(eps))
    res["shape_error_max_m"] = to_float(peak_abs(eps))
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


def crest_factor_issues(mdf: pd.DataFrame) -> list[Issue]:
    """A warning per member and axis whose ISO 2631 crest factor exceeds 9 (clause 6.2.1),
    with the additional methods' values (clause 6.3) and their ratios to the basic value."""
    out = []
    for mid, r in mdf.iterrows():
        for ax in ("lon", "lat"):
            flag = r.get(f"aw_crest_over_9_{ax}")
            if not (isinstance(flag, (bool, np.bool_)) and flag):
                continue
            aw, dur = r.get(f"aw_{ax}_mps2"), r.get("duration_s")
            mtvv, vdv = r.get(f"mtvv_{ax}_mps2"), r.get(f"vdv_{ax}_mps175")
            ratio_v = vdv / (aw * dur ** 0.25) if aw and dur else math.nan
            out.append(Issue(
                "warning", "iso2631_crest_factor", f"{mid} a_{ax}",
                f"crest factor {r.get(f'aw_crest_{ax}'):.1f} > {iso2631.CREST_FACTOR_LIMIT:g}: the "
                f"basic r.m.s. a_w = {aw:.3g} m/s^2 may underestimate shocks (ISO 2631-1 6.2.1); "
                f"MTVV {mtvv:.3g} m/s^2 (MTVV / a_w = {mtvv / aw:.2f}, 6.3.3: 1.5), VDV "
                f"{vdv:.3g} m/s^1.75 (VDV / (a_w T^1/4) = {ratio_v:.2f}, 6.3.3: 1.75)"))
    return out


def _worst(mdf: pd.DataFrame) -> dict[str, float | None]:
    """Largest value over the members of every KEY_METRICS column (None: no data)."""
    worst = {}
    for k in KEY_METRICS:
        col = pd.to_numeric(mdf[k], errors="coerce")
        worst[k] = to_float(col.max()) if col.notna().any() else None
    return worst


def compute_run(data: RunData, settings: AnalysisSettings = DEFAULT_SETTINGS,
                baseline: BaselineData | None = None) -> RunAnalysis:
    """Compute every metric of a loaded run.

    Parameters
    ----------
    data : RunData
        Output of :func:`analysis.load.run_data.load_run`.
    settings : AnalysisSettings
        Analysis choices; default :data:`DEFAULT_SETTINGS`.
    baseline : BaselineData, optional
        Twin run without the formation (:func:`analysis.runs.traffic_run.load_baseline`) for
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
        out, why, sig = member_metrics(data, mem, vc, settings)
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
    issues += crest_factor_issues(mdf)
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
        duration_s=covered_time_s(np.unique(t_all),
                                  contiguous_segments(np.unique(t_all), dt, GAP_FACTOR)
                                  if math.isfinite(dt) else [slice(0, np.unique(t_all).size)]),
        n_members=len(members), n_members_with_data=int(mdf["n_samples"].notna().sum()),
        **shape_res, **energy.run,
        **{k: (meta.get("incidents") or {}).get(k) for k in INCIDENT_KEYS},
    )
    if len(ss):
        run.update(string_stable=bool(not ss["amplifies"].any()),
                   string_peak_ratio_max=to_float(ss["peak_ratio"].max()),
                   string_rms_ratio_max=to_float(ss["rms_ratio"].max()))
    dt_iso = control_rate_dt(data) if math.isfinite(control_rate_dt(data)) else dt
    if math.isfinite(dt_iso):  # ISO 2631 from comfort.parquet (control rate) when recorded
        issues += _iso2631_band(run, 1.0 / dt_iso, dt_iso)
    run["worst"] = _worst(mdf)
    return RunAnalysis(data=data, settings=settings, run=run, members=mdf,
                       string_stability=ss, unavailable=unavailable, signals=signals,
                       shape=shape_df, issues=tuple(issues), traffic=tra, energy=energy,
                       comm_age=comm_age,
                       formations=tuple(formation_amplification(
                           traj, {m.id: m.offset for m in members
                                  if np.isfinite(m.offset).all()}, settings.column_dy_tol_m, meta)))
