"""A toy control law defined outside the package (tests/test_law_seam.py, tests/test_law_params.py):
every member drives straight ahead at the speed ``v_set`` [m/s] of its parameter row (the
scenario's ``[controller.<name>]``, by the module's SPEC; 12.5 by default), whatever the formation: the
unicycle gets v_set as its speed input, the dynamic model a_r = 2 (v_set - v) [m/s^2] (a first
order approach with time constant 0.5 s) and no steering."""
import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field

NAME = "toy_constant_speed"
"""The name the tests register it under (``register_law(NAME, toy_law)``)."""
PARAMS = ("v_set",)
V_SET = 12.5


class SPEC(BaseModel):
    """[controller.<name>] of the toy law."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    v_set: float = Field(V_SET, gt=0.0, description="the speed every member drives at [m/s]")


def pack(cfg):
    per = cfg.law_params if cfg.law_params is not None else ({},) * cfg.n
    return np.array([[float(p.get(NAME, {}).get("v_set", V_SET))] for p in per]).reshape(cfg.n, 1)


@njit(cache=False)
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    x = state.x
    v = fleet.L[i, 0]
    u0 = v if fleet.kind == 0 else 2.0 * (v - x[i, 3])
    return u0, 0.0, v, 0.0, 0.0, 0.0, target.px - x[i, 0], target.py - x[i, 1], 0.0
