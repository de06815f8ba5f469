"""Communication metrics: the age of the virtual-car state each member held, and how the
formation error and the comfort depend on it (docs/communication.md).

Works on the recorded ``leader_age_s`` column (0 throughout with perfect communication; NaN
in recordings made before the column existed).
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

__all__ = ["AGE_BIN_EDGES_S", "COMM_MEMBER_METRICS", "AGE_BIN_COLUMNS", "comm_analysis"]

AGE_BIN_EDGES_S: tuple[float, ...] = (0.0, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, math.inf)
"""Edges of the age bins [s]; bin k is [edge k, edge k+1)."""

COMM_MEMBER_METRICS: dict[str, str] = {
    "leader_age_mean_s": "s", "leader_age_p50_s": "s", "leader_age_p95_s": "s",
    "leader_age_max_s": "s",
    "e_age_slope_m_per_s": "m/s",  # least-squares slope of |e| against the age
    "e_age_spearman": "-",  # rank correlation of |e| and the age
}
"""Per-member communication metrics with their units (joined to the member table)."""

AGE_BIN_COLUMNS: dict[str, str] = {
    "id": "-", "age_lo_s": "s", "age_hi_s": "s", "n": "-", "share": "-",
    "e_rms_m": "m", "a_lon_rms_mps2": "m/s^2", "a_lat_rms_mps2": "m/s^2",
    "jerk_lon_rms_mps3": "m/s^3", "jerk_lat_rms_mps3": "m/s^3",
}
"""Columns of the age-bin table (one row per member and non-empty age bin)."""


def _rms(x: np.ndarray) -> float | None:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if x.size else None


def _member(age: np.ndarray, e: np.ndarray) -> dict[str, float | None]:
    out: dict[str, float | None] = {k: None for k in COMM_MEMBER_METRICS}
    ok = np.isfinite(age)
    if not ok.any():
        return out
    a = age[ok]
    out.update(leader_age_mean_s=float(a.mean()), leader_age_p50_s=float(np.percentile(a, 50)),
               leader_age_p95_s=float(np.percentile(a, 95)), leader_age_max_s=float(a.max()))
    both = ok & np.isfinite(e)
    if both.sum() >= 3 and np.ptp(age[both]) > 0:
        out["e_age_slope_m_per_s"] = float(np.polyfit(age[both], e[both], 1)[0])
        rho = pd.Series(age[both]).rank().corr(pd.Series(e[both]).rank())
        out["e_age_spearman"] = float(rho) if np.isfinite(rho) else None
    return out


def comm_analysis(trajectories: pd.DataFrame, signals: pd.DataFrame,
                  member_ids: list[str]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Age distribution per member and error / comfort per age bin.

    Parameters
    ----------
    trajectories : DataFrame
        Recorded rows (``t``, ``vehicle_id``, ``leader_age_s`` [s], ``a_lon``, ``a_lat``
        [m/s^2]).
    signals : DataFrame
        Derived series of the analysis (``t``, ``vehicle_id``, ``e_norm`` [m], ``jerk_lon``,
        ``jerk_lat`` [m/s^3]).
    member_ids : list of str
        Members to report.

    Returns
    -------
    (DataFrame, DataFrame)
        Per member (index ``id``, columns :data:`COMM_MEMBER_METRICS`), and per member and
        age bin (:data:`AGE_BIN_COLUMNS`).
    """
    cols = ["t", "vehicle_id", "leader_age_s", "a_lon", "a_lat"]
    tr = trajectories.reindex(columns=cols)
    tr = tr[tr["vehicle_id"].isin(member_ids)]
    sig = signals.reindex(columns=["t", "vehicle_id", "e_norm", "jerk_lon", "jerk_lat"])
    tr = tr.astype({"t": "float64"})
    sig = sig.astype({"t": "float64"})
    tr["vehicle_id"] = tr["vehicle_id"].astype(str)
    sig["vehicle_id"] = sig["vehicle_id"].astype(str)
    df = tr.merge(sig, on=["t", "vehicle_id"], how="left")
    rows, bins = [], []
    edges = np.asarray(AGE_BIN_EDGES_S)
    for mid in member_ids:
        g = df[df["vehicle_id"] == mid]
        f = {c: pd.to_numeric(g[c], errors="coerce").to_numpy(dtype=float)
             for c in cols[2:] + ["e_norm", "jerk_lon", "jerk_lat"]}
        age = f["leader_age_s"]
        rows.append({"id": mid, **_member(age, f["e_norm"])})
        n_ok = int(np.isfinite(age).sum())
        k = np.searchsorted(edges, age, side="right") - 1
        for b in range(len(edges) - 1):
            sel = np.isfinite(age) & (k == b)
            if not sel.any():
                continue
            bins.append({"id": mid, "age_lo_s": float(edges[b]), "age_hi_s": float(edges[b + 1]),
                         "n": int(sel.sum()), "share": float(sel.sum() / n_ok),
                         "e_rms_m": _rms(f["e_norm"][sel]), "a_lon_rms_mps2": _rms(f["a_lon"][sel]),
                         "a_lat_rms_mps2": _rms(f["a_lat"][sel]),
                         "jerk_lon_rms_mps3": _rms(f["jerk_lon"][sel]),
                         "jerk_lat_rms_mps3": _rms(f["jerk_lat"][sel])})
    members = pd.DataFrame(rows, columns=["id", *COMM_MEMBER_METRICS]).set_index("id")
    return members, pd.DataFrame(bins, columns=list(AGE_BIN_COLUMNS))
