"""Ploeg's CACC's parameters (control/laws/cacc_ploeg.py) with their defaults, Plexe's: the
scenario's ``controller.cacc_ploeg``. Imports no kernels: the scenario schema reads it without
compiling the law."""
from __future__ import annotations

from pydantic import Field

from ...core.spec import NonNegFloat, PosFloat, Strict, defaults


class CaccPloegSpec(Strict):
    """controller.cacc_ploeg: Ploeg's constant-time-gap CACC (control/laws/cacc_ploeg.py)."""

    h_s: PosFloat = Field(0.5, description="time gap h [s]")
    kp: PosFloat = Field(0.2, description="gap gain kp [1/s^2]")
    kd: PosFloat = Field(0.7, description="gap-rate gain kd [1/s]")
    standstill_m: NonNegFloat = Field(2.0, description="standstill gap r0 [m]")


SPEC = CaccPloegSpec
DEFAULTS = defaults(SPEC)
