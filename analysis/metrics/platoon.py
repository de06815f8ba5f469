"""String amplification of a formation's columns (docs/platoon_laws.md): the
metrics.json formation-level ``string_amplification``.

Along a column (analysis/metrics/formation.py ``formation_columns``: one lateral offset, front to
back) member k's speed error is its speed less its predecessor's, e_k(t) = v_k(t) - v_(k-1)(t)
[m/s]; the amplification is max_t |e_last| / max_t |e_first| with ``first`` the member right behind
the head and ``last`` the column's tail: <= 1 string stable (errors shrink down the column). For a
linear homogeneous column e_k = Gamma e_(k-1) with Gamma = V_k / V_(k-1) the law's string
transfer function, so over a steady sinusoid of frequency w the ratio is |Gamma(jw)|^(n-2).
The record also holds |Gamma(jw)| estimated from the recorded speeds at the head's dominant
frequency f0 (:func:`gamma_estimate`: the ratio of the speeds' DFT magnitudes at f0, member by
member behind the first follower; ``gamma_mean`` their geometric mean).
The record's ``min_gap_m`` is the smallest bumper-to-bumper gap between consecutive members
of any of the formation's columns over the run (:func:`column_min_gap`; negative: the bodies
overlap), with the follower (``min_gap_member``) and the time (``min_gap_t_s``).
When the first follower's peak speed error is below :data:`AMPLIFICATION_FLOOR_MPS` there is
no error to propagate: ``string_amplification`` is None and ``string_amplification_unavailable``
says why (the virtual structure's members each track their own slot of the virtual car: their
speed errors are round-off in free space, millimetres per second of tracking on a road; their
quotient is noise, not a property of the law). A tail's peak below
:data:`SPEED_ERROR_FLOOR_MPS` counts as that floor.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.metrics import formation
from analysis.metrics.footprint import member_footprints

SPEED_ERROR_FLOOR_MPS = 1e-6
"""Peak speed errors below this are round-off [m/s]."""
AMPLIFICATION_FLOOR_MPS = 0.05
"""The first follower's peak speed error [m/s] below which ``string_amplification`` is None:
0.18 km/h, under 2 % of the bundled sinusoid's 2.78 m/s swing and under a speedometer's
resolution; a ratio of smaller errors measures tracking noise, not how a law passes errors on."""

COMPARE_ROWS = ("string_amplification", "gamma_mean")
"""Formation-level rows of ``formation-traci compare`` (the run's first formation): our column
against SUMO's CACC twin (docs/platoon_laws.md) side by side."""


def compare_value(analysis, key: str):
    """The comparison table's value of ``key`` for a RunAnalysis: run-level, or (a
    :data:`COMPARE_ROWS` key) its first formation's record (None without one)."""
    if key not in COMPARE_ROWS:
        return analysis.run.get(key)
    return analysis.formations[0].get(key) if analysis.formations else None


def amplification(speeds: np.ndarray) -> tuple[float | None, float, float]:
    """(ratio, peak |e_first| [m/s], peak |e_last| [m/s]) of a column's speeds (n >= 3 members,
    front to back, shape (n, n_t), no NaN); the ratio is None when peak |e_first| is below
    :data:`AMPLIFICATION_FLOOR_MPS` (no error to propagate)."""
    e = np.abs(np.diff(np.asarray(speeds, float), axis=0))  # row k-1: |v_k - v_(k-1)|
    first = float(e[0].max())
    last = float(e[-1].max())
    if first < AMPLIFICATION_FLOOR_MPS:
        return None, first, last
    return max(last, SPEED_ERROR_FLOOR_MPS) / first, first, last


def _no_error_reason(first: float) -> str:
    return (f"the first follower's peak speed error {first:.3g} m/s is below "
            f"{AMPLIFICATION_FLOOR_MPS:g} m/s: no error to propagate")


def column_min_gap(traj: pd.DataFrame, column: list, bodies: dict) -> tuple:
    """(gap [m], follower id, t [s]) of the smallest bumper-to-bumper gap between consecutive
    members of ``column`` (front to back): the centres of gravity's distance along the
    follower's heading less the predecessor's CoG-to-rear and the follower's CoG-to-front
    (``bodies``: id -> analysis/metrics/footprint.py Footprint; control/laws/platoon.py ``gap_at``);
    (None, None, None) without common samples."""
    w = traj.loc[traj["vehicle_id"].isin(column)].pivot(index="t", columns="vehicle_id",
                                                         values=["x", "y", "heading"])
    best = (None, None, None)
    for ahead, me in zip(column, column[1:]):
        if me not in w["x"] or ahead not in w["x"] or me not in bodies or ahead not in bodies:
            continue
        h = w["heading"][me]
        g = ((w["x"][ahead] - w["x"][me]) * np.cos(h) + (w["y"][ahead] - w["y"][me]) * np.sin(h)
             - (bodies[ahead].length - bodies[ahead].cog_to_front) - bodies[me].cog_to_front).dropna()
        if len(g) and (best[0] is None or g.min() < best[0]):
            best = (float(g.min()), str(me), float(g.idxmin()))
    return best


def formation_amplification(traj: pd.DataFrame, offsets: dict, dy_tol: float,
                            meta: dict | None = None) -> list[dict]:
    """One record per formation (trajectories' ``formation_id``): its largest column
    amplification with the column's members (front to back) and the two peaks; None where no
    column has three members with common samples. With run.json (``meta``: the members' bodies,
    analysis/metrics/footprint.py) also the smallest gap of its columns (``min_gap_m``,
    ``min_gap_member``, ``min_gap_t_s``; None without ``meta``)."""
    bodies = {} if meta is None else member_footprints(meta.get("scenario"), meta.get("members"))
    fids = traj.drop_duplicates("vehicle_id").set_index("vehicle_id")["formation_id"] \
        if "formation_id" in traj.columns else None
    out = []
    groups = sorted(set(fids.loc[fids.index.isin(offsets)].astype(str))) if fids is not None \
        else ["f0"]
    for fid in groups:
        own = {m: o for m, o in offsets.items() if fids is None or str(fids.get(m)) == fid}
        best, gap = None, (None, None, None)
        for column in formation.formation_columns(own, dy_tol):
            g = column_min_gap(traj, column, bodies)
            if g[0] is not None and (gap[0] is None or g[0] < gap[0]):
                gap = g
            v = traj.loc[traj["vehicle_id"].isin(column)].pivot(
                index="t", columns="vehicle_id", values="v")
            present = [c for c in column if c in v.columns]
            v = v[present].dropna()
            if len(present) < 3 or len(v) == 0:
                continue
            r, first, last = amplification(v.to_numpy().T)
            if best is None or _ranks_above(r, best["string_amplification"]):
                best = {"id": fid, "string_amplification": r, "column": present,
                        "peak_speed_error_first_mps": first, "peak_speed_error_last_mps": last,
                        "string_amplification_unavailable": None if r is not None
                        else _no_error_reason(first),
                        **_gamma_record(v.to_numpy().T, np.diff(v.index.to_numpy()))}
        out.append({**(best or {"id": fid, "string_amplification": None, "column": [],
                                "peak_speed_error_first_mps": None, "peak_speed_error_last_mps": None,
                                "string_amplification_unavailable": "no column of three members "
                                "with common samples",
                                "gamma_f0_hz": None, "gamma": [], "gamma_mean": None}),
                    "min_gap_m": gap[0], "min_gap_member": gap[1], "min_gap_t_s": gap[2]})
    return out


def _ranks_above(r, best) -> bool:
    """Does a column's ratio ``r`` replace the best so far (None: below the floor, ranks
    lowest)?"""
    if r is None:
        return False
    return best is None or r > best


def _gamma_record(v: np.ndarray, steps: np.ndarray) -> dict:
    """The record's |Gamma| estimate (:func:`gamma_estimate`; None for uneven samples or fewer
    than four members)."""
    if v.shape[0] < 4 or len(steps) == 0 or np.ptp(steps) > 1e-9 * steps.max():
        return {"gamma_f0_hz": None, "gamma": [], "gamma_mean": None}
    f0, g = gamma_estimate(v, float(steps.mean()))
    ok = np.isfinite(g) & (g > 0)
    return {"gamma_f0_hz": f0, "gamma": [float(x) for x in g],
            "gamma_mean": float(np.exp(np.log(g[ok]).mean())) if ok.all() else None}


def dominant_frequency(v: np.ndarray, dt: float, f_lo: float = 0.02, f_hi: float = 2.0,
                       df: float = 0.002) -> float:
    """The frequency [Hz] of the largest DFT magnitude of ``v`` (its mean removed) on a grid
    f_lo .. f_hi step df (samples every dt [s])."""
    f = np.arange(f_lo, f_hi + df / 2, df)
    return float(f[np.argmax(np.abs(dft_at(v, dt, f)))])


def dft_at(v: np.ndarray, dt: float, f) -> np.ndarray:
    """sum_k (v_k - mean v) exp(-2 pi i f k dt) at each frequency f [Hz]."""
    v = np.asarray(v, float)
    k = np.arange(v.shape[-1]) * dt
    return np.exp(-2j * np.pi * np.outer(np.atleast_1d(f), k)) @ (v - v.mean(axis=-1, keepdims=True)).T


def gamma_estimate(speeds: np.ndarray, dt: float) -> tuple[float, np.ndarray]:
    """The string transfer function's magnitude |Gamma(j 2 pi f0)| estimated from a column's
    speeds (front to back, (n, n_t), every dt [s]) at f0, the head's dominant frequency:
    (f0 [Hz], |V_k(f0)| / |V_(k-1)(f0)| for k = 2 .. n-1, the pairs behind the first follower)."""
    v = np.asarray(speeds, float)
    f0 = dominant_frequency(v[0], dt)
    mag = np.abs(dft_at(v, dt, f0)).ravel()
    with np.errstate(divide="ignore", invalid="ignore"):
        return f0, mag[2:] / mag[1:-1]
