"""A toy model variant defined outside the package (tests/test_model_variant.py): the dynamic
bicycle (models/bicycle.py) with one more state slot, an odometer ODO [m] that integrates the
speed, d ODO / dt = scale v, ``scale`` [-] its calibration (the scenario's
``[vehicle.toy_odometer]``, by the module's SPEC; 1, the true distance, by default). The
odometer feeds nothing back: the bicycle's slots move as they do without it."""
import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field

from formation_traci.models import bicycle
from formation_traci.models.params import N_PARAMS

NAME = "toy_odometer"
"""The name the tests register it under (``register_model(NAME, toy_slot)``)."""
BASE = "dynamic"
SLOTS = ("ODO",)
ODO = bicycle.N_STATES
"""The odometer's column in a member's state row (after the bicycle's slots)."""
SCALE = N_PARAMS
"""The calibration's column in a member's parameter row (after the bicycle's)."""
V = int(bicycle.S.V)


class SPEC(BaseModel):
    """[vehicle.<name>] of the toy variant."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    scale: float = Field(1.0, gt=0.0, description="the odometer's calibration [-]: it reads scale x distance")


def pack(cfg):
    return np.full((cfg.n, 1), float(cfg.variant_params["scale"]))


@njit(cache=False)
def rhs_into(s, u0, u1, P, i, out):
    bicycle.rhs_into(s, u0, u1, P, i, out)
    out[ODO] = P[i, SCALE] * s[V]
