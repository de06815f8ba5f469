"""Maneuvers in a recorded run: their intervals from events.parquet, and error and comfort
split between steady driving and maneuvers (docs/maneuvers.md, docs/metrics.md).

A maneuver interval runs from a ``maneuver_start`` event to the next ``maneuver_end`` (or the
end of the record when the run stopped during it). The maneuver's name is the first word of
the events' ``detail`` (``reshape: T = ...``). Metrics are pure functions of the arrays.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["MANEUVER_COLUMNS", "PHASE_METRICS", "maneuver_intervals", "in_intervals",
           "phase_metrics"]

MANEUVER_COLUMNS = ("name", "start_s", "end_s", "completed")
"""Columns of :func:`maneuver_intervals`."""

PHASE_METRICS: dict[str, str] = {
    "duration_s": "s", "e_rms_m": "m", "e_max_m": "m", "e_lat_rms_m": "m",
    "a_lat_peak_mps2": "m/s^2", "a_lat_rms_mps2": "m/s^2", "a_lon_peak_mps2": "m/s^2",
}
"""Per member and phase (steady / maneuver), with units."""


def maneuver_intervals(events: pd.DataFrame | None, t_end: float) -> pd.DataFrame:
    """Intervals of the run's maneuvers, one row each (columns MANEUVER_COLUMNS).

    Parameters
    ----------
    events : DataFrame or None
        events.parquet (t [s], kind, detail).
    t_end : float
        Last recorded time [s]: the end of a maneuver still running then.

    Returns
    -------
    DataFrame
        name, start_s [s], end_s [s], completed (False: still running at t_end).
    """
    rows = []
    if events is not None and len(events):
        ev = events[events["kind"].isin(["maneuver_start", "maneuver_end"])].sort_values("t", kind="stable")
        open_ = None
        for t, kind, detail in zip(ev["t"], ev["kind"], ev["detail"].astype(str)):
            name = detail.split(":")[0].strip()
            if kind == "maneuver_start":
                open_ = (name, float(t))
            elif open_ is not None:
                rows.append((open_[0], open_[1], float(t), True))
                open_ = None
        if open_ is not None:
            rows.append((open_[0], open_[1], float(t_end), False))
    return pd.DataFrame(rows, columns=list(MANEUVER_COLUMNS))


def in_intervals(t, intervals: pd.DataFrame) -> np.ndarray:
    """Which times fall inside any interval (ends included).

    Parameters
    ----------
    t : array_like
        Times [s].
    intervals : DataFrame
        :func:`maneuver_intervals` (start_s, end_s [s]).

    Returns
    -------
    ndarray of bool, shape of t
    """
    t = np.asarray(t, dtype=float)
    mask = np.zeros(t.shape, dtype=bool)
    for a, b in zip(intervals["start_s"], intervals["end_s"]):
        mask |= (t >= a) & (t <= b)
    return mask


def _phase(g: pd.DataFrame, dt: float) -> dict[str, float]:
    def peak(x):
        x = np.abs(np.asarray(x, float))
        return float(np.nanmax(x)) if np.isfinite(x).any() else np.nan

    def rms(x):
        x = np.asarray(x, float)
        x = x[np.isfinite(x)]
        return float(np.sqrt(np.mean(x * x))) if x.size else np.nan

    e = np.hypot(g["e_lon"].to_numpy(float), g["e_lat"].to_numpy(float))
    return {"duration_s": len(g) * dt, "e_rms_m": rms(e), "e_max_m": peak(e),
            "e_lat_rms_m": rms(g["e_lat"]), "a_lat_peak_mps2": peak(g["a_lat"]),
            "a_lat_rms_mps2": rms(g["a_lat"]), "a_lon_peak_mps2": peak(g["a_lon"])}


def phase_metrics(traj: pd.DataFrame, member_ids, intervals: pd.DataFrame, dt: float) -> pd.DataFrame:
    """PHASE_METRICS per member and phase: index (id, phase), phase 'steady' or 'maneuver'.

    Parameters
    ----------
    traj : DataFrame
        trajectories.parquet (t, vehicle_id, e_lon, e_lat, a_lat, a_lon).
    member_ids : sequence of str
        Members to evaluate.
    intervals : DataFrame
        :func:`maneuver_intervals`.
    dt : float
        Sample spacing [s] (duration = samples * dt).

    Returns
    -------
    DataFrame
        PHASE_METRICS [units there], index (id, phase).
    """
    rows = []
    for mid in member_ids:
        g = traj[traj["vehicle_id"] == mid]
        during = in_intervals(g["t"], intervals)
        for phase, sel in (("steady", ~during), ("maneuver", during)):
            rows.append({"id": mid, "phase": phase, **_phase(g[sel], dt)})
    cols = ["id", "phase", *PHASE_METRICS]
    return pd.DataFrame(rows, columns=cols).set_index(["id", "phase"])
