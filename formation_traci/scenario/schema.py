"""Scenario schema: a TOML document validated into frozen, typed objects.

Every table forbids unknown keys; defaults live here and nowhere else. Field units are in
the names (``_deg``, ``_deg_s``) or in the field descriptions (SI otherwise).
See docs/scenarios.md for the field-by-field reference.
"""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

PosFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Pair = Annotated[list[Finite], Field(min_length=2, max_length=2)]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class ProfileSpec(Strict):
    """A piecewise signal: values at knot times, linear or smoothstep between."""

    t: list[NonNegFloat] = Field(min_length=1, description="knot times [s], strictly increasing")
    values: list[Finite] = Field(min_length=1, description="signal at the knots")
    interp: Literal["linear", "smooth"] = "linear"

    @model_validator(mode="after")
    def _knots(self):
        if len(self.t) != len(self.values):
            raise ValueError(f"t and values must have the same length (got {len(self.t)} and {len(self.values)})")
        if any(b <= a for a, b in zip(self.t, self.t[1:])):
            raise ValueError("t must be strictly increasing")
        return self


Signal = Union[Finite, ProfileSpec]


class RunSpec(Strict):
    duration: PosFloat = Field(description="simulated time [s]")
    step: PosFloat = Field(0.05, description="outer step: recording interval and SUMO step length [s]")
    control_step: PosFloat = Field(0.01, description="controller sampling period [s]; divides step")
    physics_step: PosFloat = Field(0.01, le=0.01, description="largest RK4 sub-step [s]; at most 0.01")
    seed: int = Field(0, ge=0, description="random seed (SUMO's --seed; recorded in run.json)")

    @model_validator(mode="after")
    def _ratios(self):
        for name, small, big in (("control_step", self.control_step, self.step),):
            r = big / small
            if abs(r - round(r)) > 1e-9 * r or round(r) < 1:
                raise ValueError(f"{name} must divide step a whole number of times "
                                 f"(step={self.step}, {name}={small})")
        if self.step > self.duration:
            raise ValueError(f"step ({self.step} s) must not exceed duration ({self.duration} s)")
        return self


class VehicleOverrides(Strict):
    """Optional replacements of preset chassis values (units as in the preset)."""

    m: PosFloat | None = Field(None, description="mass [kg]")
    Izz: PosFloat | None = Field(None, description="yaw inertia [kg m^2]")
    a: PosFloat | None = Field(None, description="CoG to front axle [m]")
    b: PosFloat | None = Field(None, description="CoG to rear axle [m]")
    h: PosFloat | None = Field(None, description="CoG height [m]")
    length: PosFloat | None = Field(None, description="body length [m]")
    width: PosFloat | None = Field(None, description="body width [m]")
    front_overhang: NonNegFloat | None = Field(None, description="front axle to bumper [m]")
    steer_max_deg: PosFloat | None = Field(None, le=89, description="steering angle limit [deg]")
    steer_rate_max_deg_s: PosFloat | None = Field(None, description="steering rate limit [deg/s]")


SURFACE_NAMES = Literal["good_dry", "good_wet", "poor_dry", "poor_wet", "ice"]


class VehicleSpec(Strict):
    model: Literal["dynamic", "kinematic"] = "dynamic"
    preset: Literal["passenger_car", "small_truck"] = "passenger_car"
    tire: Literal["load", "seed"] = Field("load", description="'load': D = -mu * axle load; 'seed': Table 3.2")
    tire_law: Literal["magic_formula", "linear"] = "magic_formula"
    surface: SURFACE_NAMES = Field("good_dry", description="Table 3.3 pavement")
    mu: PosFloat | None = Field(None, le=1.5, description="road adhesion [-]; overrides surface")
    params: VehicleOverrides = VehicleOverrides()


class GainSpec(Strict):
    g_min: PosFloat
    g_max: PosFloat
    k_min: PosFloat

    @model_validator(mode="after")
    def _order(self):
        if self.g_max < self.g_min:
            raise ValueError(f"g_max ({self.g_max}) must be >= g_min ({self.g_min})")
        return self


GAIN_TABLES = Literal["table_3_4", "table_3_6", "table_3_7", "table_3_8", "table_3_12"]


class ControllerSpec(Strict):
    k: PosFloat = Field(1.0, description="position gain of (2.7) [m/s]")
    k_theta: PosFloat = Field(3.0, description="heading gain of (2.8) [1/s]")
    speed_gains: GAIN_TABLES | GainSpec = Field(
        "table_3_4", description="linear-velocity schedule (3.34); 'table_3_6' for the truck")
    yaw_gains: GAIN_TABLES | GainSpec = Field("table_3_8", description="angular-velocity schedule (3.34)")


class LeaderSpec(Strict):
    """Virtual car (eq 2.3) in free space."""

    x: Finite = Field(0.0, description="initial x [m]")
    y: Finite = Field(0.0, description="initial y [m]")
    heading_deg: Finite = Field(0.0, description="initial heading [deg], counter-clockwise from +x")
    speed: Signal = Field(description="speed [m/s]: constant or profile")
    yaw_rate_deg_s: Signal = Field(0.0, description="yaw rate [deg/s]: constant or profile")

    @field_validator("speed")
    @classmethod
    def _speed_nonneg(cls, v):
        vals = v.values if isinstance(v, ProfileSpec) else [v]
        if any(x < 0 for x in vals):
            raise ValueError("speed must be >= 0 m/s")
        return v


class MemberSpec(Strict):
    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")
    offset: Pair = Field(description="[d_x, d_y] in the virtual car frame [m], eq 2.4")
    position: Pair = Field(description="initial centre of gravity [x, y] [m]")
    heading_deg: Finite | None = Field(None, description="initial heading [deg]; default the leader's")
    speed: NonNegFloat | None = Field(None, description="initial speed [m/s]; default the leader's")
    yaw_rate_deg_s: Finite = Field(0.0, description="initial yaw rate [deg/s] (dynamic model)")
    steer_deg: Finite = Field(0.0, description="initial steering angle [deg] (dynamic model)")
    k: PosFloat | None = Field(None, description="per-member override of controller.k")
    k_theta: PosFloat | None = Field(None, description="per-member override of controller.k_theta")


class Scenario(Strict):
    name: str = ""
    description: str = ""
    run: RunSpec
    vehicle: VehicleSpec = VehicleSpec()
    controller: ControllerSpec = ControllerSpec()
    leader: LeaderSpec
    members: list[MemberSpec] = Field(min_length=1, description="at least one member")

    @model_validator(mode="after")
    def _unique_ids(self):
        ids = [m.id for m in self.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"member ids must be unique, repeated: {dup}")
        if "vc" in ids:
            raise ValueError("member id 'vc' is reserved for the virtual car")
        return self
