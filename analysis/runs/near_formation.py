"""Background traffic near the formation: the formation's window along the road at each
step, the vehicles inside it (behind, alongside, ahead) and their speeds and time loss.

Part of the per-run traffic computation (:mod:`analysis.runs.traffic_run`). Definitions:
``docs/metrics.md``, section "Traffic interaction".
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from analysis.metrics import traffic as tr
from analysis.metrics.conflicts import time_keys
from analysis.runs.settings import AnalysisSettings


def _near_window(M: pd.DataFrame, rng: float) -> pd.DataFrame:
    """Per step: the formation's extent along the road (rearmost rear bumper, foremost
    front bumper) and the window ``rng`` beyond it on either side."""
    m = M.dropna(subset=["s"])
    g = pd.DataFrame({"key": m["key"], "rear": m["s"] - 0.5 * m["length"],
                      "front": m["s"] + 0.5 * m["length"]}).groupby("key")
    return pd.DataFrame({"rear": g["rear"].min(), "front": g["front"].max()}).assign(
        w_lo=lambda w: w["rear"] - rng, w_hi=lambda w: w["front"] + rng)


def near_rows(bg: pd.DataFrame, win: pd.DataFrame, dt: float) -> pd.DataFrame:
    """Background rows whose centre is inside the formation's window at their step, with
    ``where``: behind (front bumper behind the formation's rear), ahead (rear bumper
    ahead of its front) or alongside."""
    if bg is None or win.empty or "s" not in bg.columns:
        return pd.DataFrame(columns=["vehicle_id", "key", "v", "lane_index", "where"])
    b = bg.assign(key=time_keys(pd.to_numeric(bg["t"], errors="coerce"), dt))
    b = b.join(win, on="key", how="inner")
    s = pd.to_numeric(b["s"], errors="coerce")
    b = b.loc[(s >= b["w_lo"]) & (s <= b["w_hi"])].copy()
    s = pd.to_numeric(b["s"], errors="coerce")
    half = 0.5 * pd.to_numeric(b.get("length", pd.Series(0.0, index=b.index)),
                               errors="coerce").fillna(0.0)
    b["where"] = np.where(s + half < b["rear"], "behind",
                          np.where(s - half > b["front"], "ahead", "alongside"))
    return b


def finite_mean(x) -> float | None:
    """Mean of the finite values of ``x`` (numbers or text read as numbers); None when none."""
    x = pd.to_numeric(pd.Series(x), errors="coerce").to_numpy(float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else None


def background_near(bg: pd.DataFrame | None, bg_ok: bool, road: bool, road_bg: bool,
                    M: pd.DataFrame, id_set: set[str], st: AnalysisSettings, dt: float,
                    run: dict[str, Any]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Background speeds and time loss (filled into ``run``); returns the formation's window
    per step and the background rows inside it (empty frames when not computable)."""
    win = _near_window(M, st.interaction_range_m) if road else pd.DataFrame()
    near = pd.DataFrame()
    if bg_ok:
        b_all = bg.loc[~bg["vehicle_id"].astype(str).isin(id_set)]
        run["bg_n_vehicles"] = int(b_all["vehicle_id"].nunique())
        if math.isfinite(dt) and dt > 0:
            v = pd.to_numeric(b_all["v"], errors="coerce")
            loss = v.groupby(b_all["vehicle_id"].astype(str)).apply(
                lambda x: float(tr.time_loss(x.to_numpy(float), dt)))
            run["bg_time_loss_total_s"] = float(loss.sum()) if len(loss) else 0.0
            run["bg_time_loss_mean_s"] = float(loss.mean()) if len(loss) else None
        if road_bg:
            near = near_rows(b_all, win, dt)
            run["bg_n_vehicles_near"] = int(near["vehicle_id"].nunique())
            run["bg_speed_mean_near_mps"] = finite_mean(near["v"])
            for w in ("behind", "alongside", "ahead"):
                run[f"bg_speed_mean_{w}_mps"] = finite_mean(near.loc[near["where"] == w, "v"])
            if len(near):
                lanes = near.assign(lane=pd.to_numeric(near["lane_index"], errors="coerce"))
                by = lanes.dropna(subset=["lane"]).groupby("lane")["v"].mean()
                run["bg_speed_mean_by_lane_mps"] = {str(int(k)): float(x)
                                                    for k, x in by.items()}

    return win, near
