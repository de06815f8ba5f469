"""The ACC law's parameters (control/laws/acc.py) with their defaults, Plexe's: the scenario's
``controller.acc``, also a CACC's fallback on radio loss (control/laws/platoon.py's ACC
block). Imports no kernels: the scenario schema reads it without compiling the law."""
from __future__ import annotations

from pydantic import Field

from ...core.spec import NonNegFloat, PosFloat, Strict, defaults


class AccSpec(Strict):
    """controller.acc: constant time gap on ego sensing (control/laws/acc.py; Plexe's defaults)."""

    headway_s: PosFloat = Field(1.2, description="time gap h [s]")
    gap_gain: PosFloat = Field(0.1, description="gap gain lambda [1/s]")
    standstill_m: NonNegFloat = Field(2.0, description="standstill gap r0 [m]")


SPEC = AccSpec
DEFAULTS = defaults(SPEC)
