"""The platoon laws' tables of ``[controller]`` (docs/platoon_laws.md): our laws' parameters
(control/laws) and ``controller.sumo_cacc``, the vType of SUMO's own CACC car-following model
that drives the followers when ``controller.law = "sumo_cacc"`` (sumo/driven.py)."""
from __future__ import annotations

from pydantic import Field, model_validator

from .base import NonNegFloat, PosFloat, Strict


class AccSpec(Strict):
    """controller.acc: constant time gap on ego sensing (control/laws/acc.py; Plexe's defaults)."""

    headway_s: PosFloat = Field(1.2, description="time gap h [s]")
    gap_gain: PosFloat = Field(0.1, description="gap gain lambda [1/s]")
    standstill_m: NonNegFloat = Field(2.0, description="standstill gap r0 [m]")


class CaccPathSpec(Strict):
    """controller.cacc_path: PATH/Rajamani constant spacing (control/laws/cacc_path.py)."""

    spacing_m: PosFloat = Field(5.0, description="constant gap d [m]")
    c1: float = Field(0.5, ge=0.0, le=1.0, description="leader weight C1 [-]")
    xi: float = Field(1.0, ge=1.0, description="damping ratio xi [-] (>= 1)")
    omega_n_hz: PosFloat = Field(0.2, description="bandwidth f_n [Hz] (w_n = 2 pi f_n)")


class CaccPloegSpec(Strict):
    """controller.cacc_ploeg: Ploeg's constant-time-gap CACC (control/laws/cacc_ploeg.py)."""

    h_s: PosFloat = Field(0.5, description="time gap h [s]")
    kp: PosFloat = Field(0.2, description="gap gain kp [1/s^2]")
    kd: PosFloat = Field(0.7, description="gap-rate gain kd [1/s]")
    standstill_m: NonNegFloat = Field(2.0, description="standstill gap r0 [m]")


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


def sumo_cacc_rules(sc):
    """``controller.law = "sumo_cacc"`` needs SUMO (a [road]) and a column SUMO can drive on
    its own: no maneuvers (they move slots SUMO's vehicles do not follow), no [comm] (SUMO's
    CACC has no radio model here). Returns ``sc`` (a Scenario model validator)."""
    if sc.controller.law != "sumo_cacc":
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
