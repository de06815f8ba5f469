"""The platoon laws' tables of ``[controller]`` (docs/platoon_laws.md): our laws' parameters
(control/laws). ``controller.sumo_cacc``, SUMO's own CACC, is its law's module's
(control/laws/sumo_cacc.py)."""
from __future__ import annotations

from pydantic import Field

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
