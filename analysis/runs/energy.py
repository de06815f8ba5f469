"""Energy of the members: traction energy per distance and the saving against driving alone.

Definitions (docs/energy.md, docs/metrics.md):

* traction energy E = integral of max(P, 0) dt, with P the recorded ``power`` [W] (traction
  power at the wheels; braking is dissipated, nothing is recovered);
* distance D = integral of v dt; energy per distance E / D, reported in kWh/100 km;
* alone: the same member driving the same speed profile with no vehicle around, i.e. with
  drag ratio 1: P_alone = P + F_drag (1 / k - 1) v, with the recorded ``drag_force`` F_drag
  [N] and ``drag_ratio`` k [-]; the saving is 1 - E / E_alone (a fraction).

Time integrals are trapezoids over each contiguous stretch of samples. Without resistances
(the seed's model, ``drag_force`` NaN) the energy is still reported, the saving is not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from analysis.load.run_data import GAP_FACTOR, Issue, RunData
from analysis.metrics.signals import contiguous_segments, trapezoid_integral

J_PER_KWH = 3.6e6
"""Joules in a kilowatt hour."""
M_PER_100KM = 1.0e5
"""Metres in 100 km."""

ENERGY_MEMBER_METRICS: dict[str, str] = {
    "distance_km": "km",
    "traction_energy_kwh": "kWh",
    "energy_kwh_per_100km": "kWh/100km",
    "energy_alone_kwh_per_100km": "kWh/100km",
    "energy_saving_vs_alone": "-",
    "drag_ratio_mean": "-",
    "drag_force_mean_n": "N",
}
"""Per-member energy metrics with their units."""

ENERGY_RUN_METRICS: dict[str, str] = {
    "energy_kwh_per_100km": "kWh/100km",
    "energy_alone_kwh_per_100km": "kWh/100km",
    "energy_saving_vs_alone": "-",
}
"""Formation-level energy metrics (all members together) with their units."""


@dataclass(frozen=True)
class EnergyAnalysis:
    """Per-member table (index id, columns ENERGY_MEMBER_METRICS), run-level values, notes."""

    members: pd.DataFrame
    run: dict[str, Any]
    unavailable: dict[str, str] = field(default_factory=dict)  # member id -> why
    issues: tuple[Issue, ...] = ()


def positive_energy(power, dt: float, segments: list[slice]) -> float:
    """Traction energy [J]: trapezoid of max(power, 0) [W] over each segment of samples."""
    p = np.clip(np.nan_to_num(np.asarray(power, dtype=float), nan=0.0), 0.0, None)
    return float(sum(trapezoid_integral(p[s], dt) for s in segments))


def distance(v, dt: float, segments: list[slice]) -> float:
    """Distance driven [m]: trapezoid of the speed v [m/s] over each segment."""
    v = np.nan_to_num(np.asarray(v, dtype=float), nan=0.0)
    return float(sum(trapezoid_integral(v[s], dt) for s in segments))


def alone_power(power, v, drag_force, drag_ratio):
    """Traction power [W] of the same motion without the vehicles around (drag ratio 1):
    P + F_drag (1 / k - 1) v."""
    power, v, f, k = (np.asarray(a, dtype=float) for a in (power, v, drag_force, drag_ratio))
    return power + f * (1.0 / k - 1.0) * v


def kwh_per_100km(energy_j: float, distance_m: float) -> float | None:
    """Energy per distance [kWh/100 km]; None for no distance."""
    if not distance_m > 0.0:
        return None
    return energy_j / J_PER_KWH / distance_m * M_PER_100KM


def _member(g: pd.DataFrame, dt: float) -> tuple[dict[str, Any], str | None, tuple[float, ...]]:
    out: dict[str, Any] = {k: None for k in ENERGY_MEMBER_METRICS}
    if g.empty or "power" not in g or not np.isfinite(g["power"].to_numpy(float)).any():
        return out, "no traction power recorded (kinematic model or column missing)", (0, 0, 0)
    t = g["t"].to_numpy(float)
    segs = contiguous_segments(t, dt, GAP_FACTOR)
    p, v = g["power"].to_numpy(float), g["v"].to_numpy(float)
    e, d = positive_energy(p, dt, segs), distance(v, dt, segs)
    out.update(distance_km=d / 1000.0, traction_energy_kwh=e / J_PER_KWH,
               energy_kwh_per_100km=kwh_per_100km(e, d))
    f = g["drag_force"].to_numpy(float) if "drag_force" in g else np.full(t.size, np.nan)
    k = g["drag_ratio"].to_numpy(float) if "drag_ratio" in g else np.full(t.size, np.nan)
    if not np.isfinite(f).any():
        return out, "resistances off: the model has no drag, no saving to compute", (e, d, math.nan)
    e_alone = positive_energy(alone_power(p, v, f, k), dt, segs)
    out.update(energy_alone_kwh_per_100km=kwh_per_100km(e_alone, d),
               energy_saving_vs_alone=(1.0 - e / e_alone) if e_alone > 0 else None,
               drag_ratio_mean=float(np.nanmean(k)), drag_force_mean_n=float(np.nanmean(f)))
    return out, None, (e, d, e_alone)


def compute_energy(data: RunData) -> EnergyAnalysis:
    """Energy metrics of every member of a loaded run and of the formation as a whole."""
    traj, dt = data.trajectories, data.dt
    rows, why, totals = [], {}, []
    for mem in data.members:
        g = traj.loc[traj["vehicle_id"] == mem.id]
        if not math.isfinite(dt):
            out, reason, tot = {k: None for k in ENERGY_MEMBER_METRICS}, "sample spacing unknown", (0, 0, 0)
        else:
            out, reason, tot = _member(g, dt)
        rows.append({"id": mem.id, **out})
        if reason:
            why[mem.id] = reason
        totals.append(tot)
    members = pd.DataFrame(rows, columns=["id", *ENERGY_MEMBER_METRICS]).set_index("id")
    run: dict[str, Any] = {k: None for k in ENERGY_RUN_METRICS}
    e, d, ea = (sum(x[j] for x in totals) for j in range(3))
    if d > 0 and e > 0:
        run["energy_kwh_per_100km"] = kwh_per_100km(e, d)
        if math.isfinite(ea) and ea > 0:
            run["energy_alone_kwh_per_100km"] = kwh_per_100km(ea, d)
            run["energy_saving_vs_alone"] = 1.0 - e / ea
    return EnergyAnalysis(members=members, run=run, unavailable=why)


def energy_rows(analysis: EnergyAnalysis) -> tuple[list[str], list[list[Any]]]:
    """Header and rows of the per-member energy table (one row per metric), for reports."""
    ids = list(analysis.members.index)
    rows = [[k, u, *[analysis.members.loc[i, k] for i in ids]]
            for k, u in ENERGY_MEMBER_METRICS.items()]
    return ["metric", "unit", *ids], rows
