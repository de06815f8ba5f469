"""SUMO's own CACC as the followers' law: ``controller.law = "sumo_cacc"`` (docs/platoon_laws.md,
"SUMO's CACC twin"), the law's definition: its parameters (:class:`SumoCaccSpec`, the
scenario's ``controller.sumo_cacc``, with SUMO's defaults, and the SUMO vType attribute each
one sets), the members it drives (:func:`driven`), the law our fleet runs for the others
(:data:`HEAD_LAW`) and what a scenario under it must meet (:func:`check_scenario`).

What drives what. The column's head (a member without predecessor, FleetConfig.pred -1) is
ours, exactly as under our platoon laws: the virtual structure on its slot of the virtual car.
Every follower is a SUMO vehicle of a vType with SUMO's ``CACC`` car-following model and these
parameters, driven by SUMO from its insertion on; SUMO's CACC follows the vehicle ahead in its
lane (MSCFModel_CACC.cpp: CACC when that vehicle's vType is CACC, else its ACC fallback; the
head's vType is CACC too, so the first follower runs CACC on it). There is no kernel here: the
SUMO side (the vType file, the followers handed to SUMO, their state read back and recorded)
is sumo/driven.py. This module imports no kernels: the scenario schema reads it.
"""
from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from ...core.spec import NonNegFloat, PosFloat, Strict
from . import DEFAULT_LAW

NAME = "sumo_cacc"
"""``controller.law`` of this law (control/laws/__init__.py SUMO_LAWS)."""
HEAD_LAW = DEFAULT_LAW
"""The law our fleet runs for the members SUMO does not drive (the column's head)."""


def driven(pred: np.ndarray) -> np.ndarray:
    """The members SUMO drives (bool, per member): the followers, every member with a
    predecessor in its column (``pred``: FleetConfig.pred, -1: none)."""
    return pred >= 0


SUMO_CACC_ATTRIBUTES = {
    "tau_s": "tau", "min_gap_m": "minGap", "accel_mps2": "accel", "decel_mps2": "decel",
    "emergency_decel_mps2": "emergencyDecel", "speed_control_gain": "speedControlGainCACC",
    "gap_closing_gain_gap": "gapClosingControlGainGap",
    "gap_closing_gain_gap_dot": "gapClosingControlGainGapDot",
    "gap_control_gain_gap": "gapControlGainGap", "gap_control_gain_gap_dot": "gapControlGainGapDot",
    "collision_avoidance_gain_gap": "collisionAvoidanceGainGap",
    "collision_avoidance_gain_gap_dot": "collisionAvoidanceGainGapDot",
    "tau_cacc_to_acc_s": "tauCACCToACC", "collision_avoidance_override_mps": "collisionAvoidanceOverride",
    "speed_control_min_gap_m": "speedControlMinGap",
}
"""controller.sumo_cacc field -> SUMO vType attribute (SUMO docs, "Car-Following-Models/CACC"
and the vType attribute table; src/microsim/cfmodels/MSCFModel_CACC.cpp)."""


class SumoCaccSpec(Strict):
    """controller.sumo_cacc: the CACC vType SUMO drives the followers with. Defaults are
    SUMO's (MSCFModel_CACC.cpp, a passenger vType's accel/decel/minGap); the desired gap,
    bumper to bumper, is min_gap_m + tau_s v (SUMO's gap2pred is the gap less minGap)."""

    tau_s: PosFloat = Field(1.0, description="time gap tau [s] (SUMO 'tau')")
    min_gap_m: NonNegFloat = Field(2.5, description="standstill gap [m] (SUMO 'minGap')")
    accel_mps2: PosFloat = Field(2.6, description="largest acceleration [m/s^2]")
    decel_mps2: PosFloat = Field(4.5, description="largest ordinary deceleration [m/s^2]")
    emergency_decel_mps2: PosFloat = Field(9.0, description="largest emergency deceleration [m/s^2]")
    speed_control_gain: float = Field(-0.4, description="speedControlGainCACC [1/s]")
    gap_closing_gain_gap: float = Field(0.005, description="gapClosingControlGainGap [1/s^2 * 0.1 s]")
    gap_closing_gain_gap_dot: float = Field(0.05, description="gapClosingControlGainGapDot [1/s * 0.1 s]")
    gap_control_gain_gap: float = Field(0.45, description="gapControlGainGap [1/s^2 * 0.1 s]")
    gap_control_gain_gap_dot: float = Field(0.0125, description="gapControlGainGapDot [1/s * 0.1 s]")
    collision_avoidance_gain_gap: float = Field(0.45, description="collisionAvoidanceGainGap")
    collision_avoidance_gain_gap_dot: float = Field(0.05, description="collisionAvoidanceGainGapDot")
    tau_cacc_to_acc_s: PosFloat = Field(1.0, description="time gap of its ACC fallback [s] (tauCACCToACC)")
    collision_avoidance_override_mps: NonNegFloat = Field(
        2.0, description="collisionAvoidanceOverride: largest excess over Krauss' safe speed [m/s]")
    speed_control_min_gap_m: NonNegFloat = Field(1.66, description="speedControlMinGap [m]")

    @model_validator(mode="after")
    def _decel_within_emergency(self):
        if self.decel_mps2 > self.emergency_decel_mps2:
            raise ValueError(
                f"decel_mps2 = {self.decel_mps2:g} m/s^2 is above emergency_decel_mps2 = "
                f"{self.emergency_decel_mps2:g} m/s^2: expected decel_mps2 <= emergency_decel_mps2 "
                "(SUMO would raise the vType's emergencyDecel to decel by itself)")
        return self

    def vtype_attributes(self) -> dict[str, str]:
        """SUMO vType attributes (name -> text) of these parameters."""
        return {SUMO_CACC_ATTRIBUTES[k]: repr(float(v)) for k, v in self.model_dump().items()}


def check_scenario(sc):
    """``controller.law = "sumo_cacc"`` needs SUMO (a [road]) and a column SUMO can drive on
    its own: no maneuvers (they move slots SUMO's vehicles do not follow), no [comm] (SUMO's
    CACC has no radio model here). Returns ``sc`` (a Scenario model validator)."""
    if sc.controller.law != NAME:
        return sc
    if sc.road is None:
        raise ValueError("controller.law = \"sumo_cacc\" needs a [road] table: SUMO's CACC "
                         "car-following model drives the followers (free space has no SUMO)")
    if sc.maneuvers:
        raise ValueError("controller.law = \"sumo_cacc\": maneuvers are not supported "
                         "(SUMO's CACC keeps its lane and follows the vehicle ahead)")
    if sc.comm is not None:
        raise ValueError("controller.law = \"sumo_cacc\": remove [comm] (SUMO's CACC reads its "
                         "leader directly, it has no radio model here)")
    return sc


SPEC = SumoCaccSpec
"""The law's parameter schema with its defaults (``controller.sumo_cacc``)."""
