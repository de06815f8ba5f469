"""``[cooperation]``: what the formations do for other traffic (docs/maneuvers.md, "Ramp traffic")."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import PosFloat, Strict


class CooperationSpec(Strict):
    merge: Literal["open_gap", "shift", "none"] = Field(
        "none", description="ramp traffic at on-ramps: 'open_gap' slows the formation, within comfort, "
        "so that a ramp vehicle meets its own safe time gap ahead of the merge lane's members "
        "(control/merge.py); 'shift' moves the whole formation one lane to the left, away from the "
        "merge lane, when a ramp vehicle is in conflict and the lane change's gap check allows it, "
        "and opens a gap as 'open_gap' does when it does not (it stays in its new lane); 'none' only "
        "observes the ramp vehicles")
    horizon_s: PosFloat = Field(10.0, le=60.0, description="ramp vehicles this far in time from their merge point are "
                                "considered [s]")
    decel_mps2: PosFloat = Field(1.5, le=3.0, description="the largest deceleration the formation yields with [m/s^2]")
    min_gap_m: PosFloat = Field(2.5, description="standstill gap added to a ramp vehicle's time gap [m]")
    merge_at: float = Field(0.5, ge=0.0, le=1.0, description="where along the acceleration lane ramp vehicles "
                            "are taken to merge [-] (0: its start, 1: its end)")
