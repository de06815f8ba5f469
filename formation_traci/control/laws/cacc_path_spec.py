"""The PATH CACC's parameters (control/laws/cacc_path.py) with their defaults, Plexe's
reference set: the scenario's ``controller.cacc_path``. Imports no kernels: the scenario
schema reads it without compiling the law."""
from __future__ import annotations

from pydantic import Field

from ...core.spec import PosFloat, Strict, defaults


class CaccPathSpec(Strict):
    """controller.cacc_path: PATH/Rajamani constant spacing (control/laws/cacc_path.py)."""

    spacing_m: PosFloat = Field(5.0, description="constant gap d [m]")
    c1: float = Field(0.5, ge=0.0, le=1.0, description="leader weight C1 [-]")
    xi: float = Field(1.0, ge=1.0, description="damping ratio xi [-] (>= 1)")
    omega_n_hz: PosFloat = Field(0.2, description="bandwidth f_n [Hz] (w_n = 2 pi f_n)")


SPEC = CaccPathSpec
DEFAULTS = defaults(SPEC)
