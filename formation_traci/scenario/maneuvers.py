"""Scenario schema of scheduled maneuvers (``[[maneuvers]]``) and their comfort limits
(``[maneuver_limits]``). See docs/maneuvers.md."""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]

MEDIUM_COMFORT_LAT = 3.6
"""Medium-comfort lateral acceleration band of the seed [m/s^2]: the largest allowed limit."""
LON_COMFORT = 2.0
"""Longitudinal comfort reference [m/s^2]: the largest allowed longitudinal limit."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class TriggerSpec(_Strict):
    """When a maneuver becomes due: exactly one of time, s or queue_behind."""

    time: NonNegFloat | None = Field(None, description="formation time [s]")
    s: NonNegFloat | None = Field(None, description="virtual car's arc length along the route [m] (as road.start)")
    queue_behind: Annotated[int, Field(ge=0)] | None = Field(
        None, description="more than this many vehicles queued behind the formation in its lanes")
    queue_reach: PosFloat = Field(100.0, description="how far behind the formation's rear a vehicle counts as queued [m]")

    @model_validator(mode="after")
    def _one(self):
        given = [k for k in ("time", "s", "queue_behind") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of 'time', 's' or 'queue_behind' (got {given or 'none'})")
        return self


class SlotSpec(_Strict):
    """A slot in road coordinates: along the reference lane and across it (left positive);
    a member's ``slot`` and each slot of a reshape's new formation."""

    along: Finite = Field(0.0, description="arc length ahead of the virtual car [m]")
    across: Finite | None = Field(None, description="lateral offset from the reference lane centre [m]")
    lanes: int | None = Field(None, description="lateral offset in lanes from the reference lane (+1 = one lane left)")

    @model_validator(mode="after")
    def _one_lateral(self):
        if (self.across is None) == (self.lanes is None):
            raise ValueError("give exactly one of 'across' [m] or 'lanes'")
        return self


class ManeuverSpec(_Strict):
    kind: Literal["reshape", "lane_change", "leave", "join"]
    at: TriggerSpec
    slots: list[SlotSpec] | None = Field(None, description="reshape: the new formation's slots (>= members)")
    lanes: int | None = Field(None, description="lane_change: shift of the whole formation in lanes (+1 = left)")
    member: str | None = Field(None, description="leave: id of the member handed over to SUMO's driver model; "
                               "join: id of the member that joins (its 'slot' is the free slot; it is not "
                               "in the formation before the join)")
    exit: str | None = Field(None, description="leave: edge id of the exit (off-ramp) SUMO routes the member to")
    vehicle: str | None = Field(None, description="join: SUMO vehicle id to take over (default: the first of "
                                "about the member's size that comes within reach)")
    reach: PosFloat = Field(30.0, description="join: take a vehicle over when its centre is this close to the free slot [m]")
    enter: SlotSpec | None = Field(None, description="join: the member's own vehicle enters the road here (relative to "
                                   "the virtual car, at its speed) under SUMO's driver when the join is due, and is "
                                   "taken over when it comes within reach")
    timeout: PosFloat = Field(30.0, description="give up when the gap check keeps refusing this long after the trigger [s]")
    check_gaps: bool = Field(True, description="start only when the target lanes have room (docs/maneuvers.md)")

    @model_validator(mode="after")
    def _fields(self):
        if self.kind == "reshape" and not self.slots:
            raise ValueError("a reshape needs 'slots' (the new formation)")
        if self.kind == "lane_change" and not self.lanes:
            raise ValueError("a lane_change needs 'lanes' (a non-zero whole number, +1 = one lane left)")
        if self.kind == "lane_change" and self.slots is not None:
            raise ValueError("a lane_change takes 'lanes', not 'slots'")
        if self.kind == "reshape" and self.lanes is not None:
            raise ValueError("a reshape takes 'slots', not 'lanes'")
        if (self.kind in ("leave", "join")) != (self.member is not None):
            raise ValueError("'member' is given with (and only with) kind = \"leave\" or \"join\"")
        if self.kind in ("leave", "join") and (self.slots is not None or self.lanes is not None):
            raise ValueError(f"a {self.kind} takes 'member', not 'slots' or 'lanes'")
        if self.exit is not None and self.kind != "leave":
            raise ValueError("'exit' is given with kind = \"leave\" only")
        if self.vehicle is not None and self.kind != "join":
            raise ValueError("'vehicle' is given with kind = \"join\" only")
        if self.enter is not None and (self.kind != "join" or self.vehicle is not None):
            raise ValueError("'enter' is given with kind = \"join\" only, and not with 'vehicle' "
                             "(the vehicle taken over is the member's own)")
        return self


class ManeuverLimits(_Strict):
    """Comfort limits that set each transition's duration, and the gap-check margins."""

    lat_accel: PosFloat = Field(1.5, le=MEDIUM_COMFORT_LAT, description="lateral acceleration of a slot [m/s^2]")
    lat_jerk: PosFloat = Field(2.5, description="lateral jerk of a slot [m/s^3] (ISO 15622: 2.5)")
    lon_accel: PosFloat = Field(1.0, le=LON_COMFORT, description="slot acceleration along the road, relative to the virtual car [m/s^2]")
    lon_jerk: PosFloat = Field(1.0, description="slot jerk along the road [m/s^3] (with the virtual car's planned jerk within a 1 m/s^3 p95)")
    min_duration: PosFloat = Field(3.0, description="shortest transition [s]")
    gap_time: NonNegFloat = Field(1.0, description="time-gap margin of the gap check [s]")
    gap_min: NonNegFloat = Field(5.0, description="standstill margin of the gap check [m]")
