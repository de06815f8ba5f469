"""SUMO's FCD output on the formation's clock and centre-of-gravity frame (``sumo.fcd_frame``).

SUMO writes ``sumo/fcd.parquet`` in its own frame: ``timestep_time`` is SUMO time (warm-up
included), ``vehicle_x``/``vehicle_y`` the front bumper, ``vehicle_angle`` degrees clockwise
from north. With ``sumo.fcd_frame = "formation"`` the file is rewritten after the run with
``t`` = formation time of the state [s] (SUMO's label + one step - warm-up: SUMO labels the
state after a step with the step's start time), ``x``/``y`` the centre of gravity of members and the body
centre of other vehicles [m], ``heading`` [rad, CCW from +x] (the frame of trajectories.parquet
and background.parquet); the other columns are kept.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .sumo_adapter import sumo_to_cog
from .traffic import BASE_TYPES


def to_formation_frame(path: Path, t0: float, member_d_front: dict[str, float], step: float) -> None:
    """Rewrite ``path`` (SUMO's FCD Parquet) in the formation's frame, in place.

    Parameters
    ----------
    path : Path
        ``sumo/fcd.parquet``.
    t0 : float
        Warm-up [s].
    member_d_front : dict
        Member id -> CoG to front bumper [m].
    step : float
        SUMO's step length [s]: SUMO labels the state after a step with the time the step
        began, so ``t = timestep_time + step - t0`` is the time the state is reached (the
        trajectories' row of the same state).
    """
    if not path.exists():
        return
    df = pd.read_parquet(path)
    ids = df["vehicle_id"].astype(str)
    types = df["vehicle_type"].astype(str) if "vehicle_type" in df else pd.Series([""] * len(df))
    half = np.full(len(df), np.nan)
    for kind, spec in BASE_TYPES.items():
        half[types.str.endswith(f"_{kind}").to_numpy()] = float(spec["length"]) / 2
    d = ids.map(member_d_front).to_numpy(dtype=float)
    d = np.where(np.isnan(d), half, d)
    x, y, psi = sumo_to_cog(df["vehicle_x"].to_numpy(float), df["vehicle_y"].to_numpy(float),
                            df["vehicle_angle"].to_numpy(float), np.nan_to_num(d))
    out = df.drop(columns=["timestep_time", "vehicle_x", "vehicle_y", "vehicle_angle"])
    out.insert(0, "t", df["timestep_time"].to_numpy(float) + step - t0)
    out.insert(2, "x", x)
    out.insert(3, "y", y)
    out.insert(4, "heading", psi)
    tmp = path.with_suffix(".tmp.parquet")
    out.to_parquet(tmp, index=False)
    tmp.replace(path)


def cut_fcd(path: Path, t0: float, step: float, t_max: float) -> None:
    """Leave out the FCD rows of states after formation time ``t_max`` [s] (the measurement
    sections' drain after the run), in place, in SUMO's frame (before any
    :func:`to_formation_frame`)."""
    if not path.exists() or not np.isfinite(t_max):
        return
    df = pd.read_parquet(path)
    keep = df["timestep_time"].to_numpy(float) + step - t0 <= t_max + 1e-9
    if keep.all():
        return
    tmp = path.with_suffix(".tmp.parquet")
    df[keep].to_parquet(tmp, index=False)
    tmp.replace(path)
