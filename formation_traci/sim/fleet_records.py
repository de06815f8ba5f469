"""The records the compiled kernels take of the members (sim/fleet.py, sumo/fused_step.py):
named tuples of arrays, built by their owners (:meth:`~.fleet.Fleet.params`,
:func:`state_record`), read by field name in the kernels."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class FleetParams(NamedTuple):
    """The members' fixed parameters over a run (sim/fleet.py Fleet)."""

    kind: int  # vehicle model code (models/state.py DYNAMIC, KINEMATIC)
    P: np.ndarray  # (n, N_PARAMS) vehicle parameters [SI] (models/params.py pack_params)
    law: np.ndarray  # (n,) control law codes in force (control/laws; changed in place)
    L: np.ndarray  # (n, n_law) law parameters [SI] (sim/fleet_laws.py pack_laws)
    gains: np.ndarray  # (n, 6) speed and yaw gain schedules: g_min, g_max, k_min of each
    pred: np.ndarray  # (n,) member ahead in the column (-1: none)
    n_sub: int  # RK4 sub-steps per control period [-]
    dt_c: float  # control period [s]


class StateRecord(NamedTuple):
    """The members' dynamic state (sim/fleet_state.py FleetState as the kernels take it)."""

    x: np.ndarray  # (n, n_states) vehicle states [SI] (models/bicycle.py S)
    theta_star: np.ndarray  # (n,) controller heading theta* (2.11) [rad]
    speed_in: np.ndarray  # (n,) unicycle only: speed input applied last [m/s]
    u_last: np.ndarray  # (n,) every member's u0 of the last control period


def as_f64(a) -> np.ndarray:
    """a as a C-contiguous, writeable float64 array (no copy when it already is one)."""
    if (type(a) is np.ndarray and a.dtype == np.float64 and a.flags.c_contiguous
            and a.flags.writeable):
        return a
    return np.array(a, dtype=np.float64, order="C")


def state_record(state) -> StateRecord:
    """A sim/fleet_state.py FleetState as the kernels take it (``u_last`` zeros when nothing
    was computed yet)."""
    ul = np.zeros(len(state.theta_star)) if state.u_last is None else as_f64(state.u_last)
    return StateRecord(as_f64(state.x), as_f64(state.theta_star), as_f64(state.speed_in), ul)
