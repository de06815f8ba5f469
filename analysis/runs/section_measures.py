"""A run's own traffic measures at its measurement sections (no twin): what a penetration-rate
study compares between its cases (docs/metrics.md, "Section measures"). Formation vehicles
(the members of every formation, ``member`` in ``sections.parquet``) and background vehicles
are measured apart.

* throughput: vehicles over the downstream (last) section during the formation's run
  [0, t_end], per hour;
* delay: per vehicle timed from the first to the last section (its first passage in
  [0, t_end]), its travel time minus the stretch at the road's speed limit;
* speed variance: of the spot speeds at every section during [0, t_end];
* conflicts: passages over a loop (section and lane) closing on the vehicle that passed it
  before, with a time to collision ``gap / closing speed`` below ``ttc_s`` or a deceleration
  rate to avoid the crash ``closing^2 / (2 gap)`` above ``drac_mps2`` (the gap from the
  leader's speed and the time between the two passages, less its length).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from analysis.runs.twin_sections import read_sections

TTC_S = 3.0
"""A section passage with a time to collision below this is a conflict [s] (as the twin comparison)."""
DRAC_MPS2 = 3.35
"""A section passage needing a deceleration above this to avoid the crash is a conflict [m/s^2]
(the usual DRAC threshold, Archer 2005)."""

SECTION_METRICS: dict[str, tuple[str, str]] = {
    "throughput_veh_h": ("veh/h", "every vehicle over the downstream section during the run"),
    "throughput_formation_veh_h": ("veh/h", "formation members over the downstream section during the run"),
    "delay_mean_s": ("s", "background vehicles timed over the stretch: mean travel time minus the stretch at the speed limit"),
    "delay_formation_mean_s": ("s", "the same for the formation members"),
    "speed_var_m2ps2": ("m^2/s^2", "variance of the background spot speeds at the sections during the run"),
    "conflicts_ttc": ("-", f"background passages closing on the vehicle ahead with TTC < {TTC_S:g} s"),
    "conflicts_ttc_formation": ("-", f"formation members' passages with TTC < {TTC_S:g} s"),
    "conflicts_drac": ("-", f"background passages with DRAC > {DRAC_MPS2:g} m/s^2"),
    "conflicts_drac_formation": ("-", f"formation members' passages with DRAC > {DRAC_MPS2:g} m/s^2"),
}
"""A run's own measures at its sections: unit and meaning (the sweep summary's columns too)."""


def _closing(p: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """The passages in loop order with, per passage, the gap to the vehicle that passed the
    same loop before [m] and the closing speed on it [m/s] (NaN: none before)."""
    q = p.sort_values(["section", "lane", "t"], kind="stable")
    same = (q["section"].eq(q["section"].shift()) & q["lane"].eq(q["lane"].shift())).to_numpy()
    v_l, t_l, len_l = (q[c].shift().to_numpy(float) for c in ("v", "t", "length"))
    gap = np.where(same, v_l * (q["t"].to_numpy(float) - t_l) - len_l, np.nan)
    closing = np.where(same, q["v"].to_numpy(float) - v_l, np.nan)
    return q, gap, closing


def section_measures(run_dir: str | Path, meta: dict, ttc_s: float = TTC_S,
                     drac_mps2: float = DRAC_MPS2) -> dict[str, Any]:
    """:data:`SECTION_METRICS` of one run (None each when it has no sections)."""
    out: dict[str, Any] = dict.fromkeys(SECTION_METRICS)
    tabs = read_sections(run_dir, meta)
    sections = (meta.get("sections") or {}).get("sections") or []
    if tabs is None or not len(tabs.passages) or len(sections) < 2:
        return out
    p, t_end = tabs.passages, tabs.t_end
    member = p["member"].astype(bool)
    last, first = int(max(s["section"] for s in sections)), int(min(s["section"] for s in sections))
    during = (p["t"] >= 0) & (p["t"] <= t_end)
    down = p[(p["section"] == last) & during]
    if t_end > 0:
        out["throughput_veh_h"] = float(down["vehicle_id"].nunique() * 3600.0 / t_end)
        out["throughput_formation_veh_h"] = float(down.loc[down["member"].astype(bool), "vehicle_id"]
                                                  .nunique() * 3600.0 / t_end)
    out["delay_mean_s"], out["delay_formation_mean_s"] = (
        _delay(p[member == m], first, last, t_end, meta) for m in (False, True))
    v = p.loc[~member & during, "v"].to_numpy(float)
    out["speed_var_m2ps2"] = float(np.var(v, ddof=1)) if v.size > 1 else None
    q, gap, closing = _closing(p[during])
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc = np.where(closing > 0, gap / closing, np.inf)
        drac = np.where((closing > 0) & (gap > 0), closing ** 2 / (2.0 * gap), 0.0)
    is_m = q["member"].astype(bool).to_numpy()
    for name, bad in (("conflicts_ttc", ttc < ttc_s), ("conflicts_drac", drac > drac_mps2)):
        out[name] = int((bad & ~is_m).sum())
        out[f"{name}_formation"] = int((bad & is_m).sum())
    return out


def _delay(p: pd.DataFrame, first: int, last: int, t_end: float, meta: dict) -> float | None:
    """Mean travel time from section ``first`` (passed in [0, t_end]) to ``last`` minus the
    stretch at the road's speed limit [s] (None: nobody timed over it)."""
    a = p[(p["section"] == first) & (p["t"] >= 0) & (p["t"] <= t_end)].groupby("vehicle_id")[["t", "s_m"]].first()
    b = p[p["section"] == last].groupby("vehicle_id")[["t", "s_m"]].first()
    both = a.add_suffix("_0").join(b.add_suffix("_1"), how="inner")
    if not len(both):
        return None
    v_limit = float((meta.get("sumo") or {}).get("speed_limit_mps") or 36.11)
    free = (both["s_m_1"] - both["s_m_0"]) / v_limit
    return float(((both["t_1"] - both["t_0"]) - free).mean())
