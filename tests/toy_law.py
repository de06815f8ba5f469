"""A toy control law defined outside the package (tests/test_law_seam.py): every member drives
straight ahead at the speed ``v_set`` [m/s] of its parameter row, whatever the formation: the
unicycle gets v_set as its speed input, the dynamic model a_r = 2 (v_set - v) [m/s^2] (a first
order approach with time constant 0.5 s) and no steering."""
import numpy as np
from numba import njit

PARAMS = ("v_set",)
V_SET = 12.5


def pack(cfg):
    return np.full((cfg.n, 1), V_SET)


@njit(cache=False)
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    x = state.x
    v = fleet.L[i, 0]
    u0 = v if fleet.kind == 0 else 2.0 * (v - x[i, 3])
    return u0, 0.0, v, 0.0, 0.0, 0.0, target.px - x[i, 0], target.py - x[i, 1], 0.0
