"""The recorder's table buffers as the compiled step takes them (sim/recorder.py
Recorder.buffers; sumo/fused_step.py): a named tuple of the same arrays over a run."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class TableBuffers(NamedTuple):
    """The tables' buffers (one row per column, one column per table row)."""

    limits: np.ndarray  # (signal columns,) bound of |signal|: beyond it a row is flagged [SI]
    traj: np.ndarray  # the trajectory table's float block: t, then the signal columns, ...
    traj_ids: np.ndarray  # its vehicle_id codes
    comfort: np.ndarray  # the comfort table's float block
    comfort_ids: np.ndarray  # its vehicle_id codes
    comfort_cols: np.ndarray  # signal column of each comfort value
    extras: np.ndarray  # the trajectory's road and SUMO columns (s, d, lane_index, sumo_gap,
    # slot, leader_age_s: record/columns.py FILLED_BY_CALLER)
    vc_cols: np.ndarray  # float-block rows of a virtual car's t, x, y, heading, v, yaw_rate,
    # a_lon, a_lat, s, d
    vc_codes: np.ndarray  # (k,) each formation's vehicle_id code
    bg_floats: np.ndarray  # the background table's float block
    bg_ints: np.ndarray  # its integer block: id, type and lane codes, lane index


class SignalRows(NamedTuple):
    """Where sim/fleet.py member_signals writes the members' rows of a step (sim/recorder.py
    Recorder.signal_rows); ``at`` < 0: nowhere."""

    limits: np.ndarray  # (signal columns,) bound of |signal|: beyond it no row is written [SI]
    traj: np.ndarray  # the trajectory table's float block
    traj_ids: np.ndarray  # its vehicle_id codes
    at: int  # the members' first row of the trajectory buffer
    comfort: np.ndarray  # the comfort table's float block
    comfort_ids: np.ndarray  # its vehicle_id codes
    c_at: int  # the members' first row of the comfort buffer
    comfort_cols: np.ndarray  # signal column of each comfort value


NO_SIGNAL_ROWS = SignalRows(np.empty(0), np.empty((0, 0)), np.empty(0, dtype=np.int32), -1,
                            np.empty((0, 0)), np.empty(0, dtype=np.int32), -1,
                            np.empty(0, dtype=np.int64))
"""member_signals' rows when none are written."""
