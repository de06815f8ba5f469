"""The member-signal array: the recorded trajectory columns the member-signal kernel
(sim/fleet.py) computes, one row per member, in the order of the trajectory table
(``run_contract.columns.TRAJECTORY_COLUMNS``)."""
from __future__ import annotations

from run_contract.columns import COMFORT_COLUMNS, TRAJECTORY_COLUMNS  # noqa: F401 (COMFORT_COLUMNS: sumo/fused_path.py)

FILLED_BY_CALLER = ("t", "vehicle_id", "s", "d", "lane_index", "sumo_gap", "slot", "leader_age_s")
"""Trajectory columns the member-signal kernel (sim/fleet.py) does not compute."""

SIGNAL_COLUMNS: tuple[str, ...] = tuple(c.name for c in TRAJECTORY_COLUMNS
                                        if c.name not in FILLED_BY_CALLER and not c.derived_from)
"""Columns of the member-signal array, in the order of TRAJECTORY_COLUMNS."""
