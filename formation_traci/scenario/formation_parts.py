"""The parts of a formation in a scenario: its vehicles, controller, virtual leader and members."""
from __future__ import annotations

from typing import Literal

from pydantic import Field, ValidationError, field_validator, model_validator

from ..control.laws import DEFAULT_LAW, SUMO_LAWS, law_names, law_spec
from ..models.variants import model_module, model_names, model_spec
from .base import Finite, NonNegFloat, Pair, PosFloat, ProfileSpec, Signal, Strict
from .maneuvers import SlotSpec


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
    c_d: PosFloat | None = Field(None, le=2.0, description="drag coefficient alone [-] (docs/energy.md)")
    frontal_area: PosFloat | None = Field(None, le=15.0, description="frontal area [m^2] (docs/energy.md)")
    drive_lag_s: NonNegFloat | None = Field(None, le=5.0, description="first-order lag of the drive/brake "
                                            "demand [s]; 0 (default): none (docs/model.md)")
    steer_lag_s: NonNegFloat | None = Field(None, le=2.0, description="first-order lag of the steering "
                                            "actuator [s]; 0 (default): none (docs/model.md)")


SURFACE_NAMES = Literal["good_dry", "good_wet", "poor_dry", "poor_wet", "ice"]


class VehicleSpec(Strict):
    model: Literal["dynamic", "kinematic"] = "dynamic"
    preset: Literal["passenger_car", "small_truck"] = "passenger_car"
    tire: Literal["load", "seed"] = Field("load", description="'load': D = -mu * axle load; 'seed': Table 3.2")
    tire_law: Literal["magic_formula", "linear"] = "magic_formula"
    surface: SURFACE_NAMES = Field("good_dry", description="Table 3.3 pavement")
    mu: PosFloat | None = Field(None, le=1.5, description="road adhesion [-]; overrides surface")
    params: VehicleOverrides = VehicleOverrides()
    variant: str | None = Field(None, description="a model variant registered at run time "
                                "(models/variants.py): the model with more state slots")
    variant_params: dict[str, dict] = Field(default_factory=dict, description=(
        "parameters of model variants, from their [vehicle.<variant>] tables, validated by each "
        "variant's SPEC (models/variants.py)"))

    @model_validator(mode="before")
    @classmethod
    def _variant_tables(cls, data):
        """[vehicle.<variant>] of a model variant with a SPEC: validated by it."""
        return _spec_tables(data, set(cls.model_fields), model_spec, "variant_params")

    @field_validator("variant_params")
    @classmethod
    def _by_their_specs(cls, given):
        return _by_specs(given, model_spec, "a model variant")

    @model_validator(mode="after")
    def _known_variant(self):
        if self.variant is None:
            return self
        if self.variant not in model_names():
            raise ValueError(f"variant: unknown model variant {self.variant!r}; registered: "
                             f"{', '.join(model_names()) or 'none'}")
        base = model_module(self.variant).BASE
        if base != self.model:
            raise ValueError(f"variant: {self.variant!r} extends the {base} model, not "
                             f"vehicle.model = {self.model!r}")
        return self


def _spec_tables(data, fields: set, spec_of, into: str):
    """A section's tables named after a registered module with a SPEC (``spec_of(name)``,
    ``[controller.<law>]``, ``[vehicle.<variant>]``) moved into its field ``into``."""
    if not isinstance(data, dict):
        return data
    tables = {k: data[k] for k in data if k not in fields and spec_of(k) is not None}
    if not tables:
        return data
    out = {k: v for k, v in data.items() if k not in tables}
    return {**out, into: {**(out.get(into) or {}), **tables}}


def _by_specs(given: dict, spec_of, what: str) -> dict:
    """Every table of ``given`` ({name: table}) validated by its module's SPEC; an error names
    the table and the field."""
    out = {}
    for name, table in given.items():
        spec = spec_of(name)
        if spec is None:
            raise ValueError(f"{name}: expected {what} with a SPEC")
        try:
            out[name] = spec.model_validate(table).model_dump()
        except ValidationError as exc:
            raise ValueError("; ".join(f"{name}.{'.'.join(map(str, e['loc']))}: {e['msg']}"
                                       for e in exc.errors())) from None
    return out


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
    law: str = Field(DEFAULT_LAW, description="the members' control law by name (control/laws): "
                     "'virtual_structure' is the seed's (2.4-2.11 with 3.32-3.38); 'acc', "
                     "'cacc_path', 'cacc_ploeg' follow the member ahead; 'sumo_cacc': SUMO's own "
                     "CACC drives the followers (road runs; docs/platoon_laws.md)")
    fallback_acc: bool = Field(
        True, description="a cacc_path / cacc_ploeg member whose [comm] beacons time out runs ACC "
        "(controller.acc) until they return; false: it keeps its CACC law on what the channel "
        "gives it (docs/platoon_laws.md, 'Fallback under bursty loss')")
    k: PosFloat = Field(1.0, description="position gain of (2.7) [m/s]")
    k_theta: PosFloat = Field(3.0, description="heading gain of (2.8) [1/s]")
    speed_gains: GAIN_TABLES | GainSpec = Field(
        "table_3_4", description="linear-velocity schedule (3.34); 'table_3_6' for the truck")
    yaw_gains: GAIN_TABLES | GainSpec = Field("table_3_8", description="angular-velocity schedule (3.34)")

    law_params: dict[str, dict] = Field(default_factory=dict, description=(
        "the laws' parameters given in their [controller.<law>] tables (controller.acc, "
        "controller.cacc_path, controller.cacc_ploeg, controller.sumo_cacc, a law registered "
        "at run time), each validated by its law's SPEC (control/laws/__init__.py); "
        "docs/scenarios.md lists the built-in laws' fields"))

    @model_validator(mode="before")
    @classmethod
    def _law_tables(cls, data):
        """[controller.<law>] of a law with a SPEC: validated by it."""
        return _spec_tables(data, set(cls.model_fields), law_spec, "law_params")

    @field_validator("law_params")
    @classmethod
    def _by_their_specs(cls, given):
        return _by_specs(given, law_spec, "a control law")

    def params(self, law: str):
        """Law ``law``'s parameters: its ``[controller.<law>]`` table over its SPEC's defaults
        (an instance of the SPEC)."""
        spec = law_spec(law)
        if spec is None:
            raise KeyError(f"control law {law!r} has no parameter schema")
        return spec.model_validate(self.law_params.get(law, {}))

    @field_validator("law")
    @classmethod
    def _known_law(cls, v):
        if v not in (*law_names(), *SUMO_LAWS):
            raise ValueError(f"unknown control law {v!r}; expected one of: "
                             f"{', '.join((*law_names(), *SUMO_LAWS))}")
        return v


class LeaderSpec(Strict):
    """Virtual car (eq 2.3) in free space."""

    x: Finite = Field(0.0, description="initial x [m]")
    y: Finite = Field(0.0, description="initial y [m]")
    heading_deg: Finite = Field(0.0, description="initial heading [deg], counter-clockwise from +x")
    speed: Signal = Field(description="speed [m/s]: constant or profile (on a road: the set speed)")
    yaw_rate_deg_s: Signal = Field(0.0, description="yaw rate [deg/s]: constant or profile (free space only)")
    time_gap: PosFloat = Field(1.5, description="time gap every member keeps to the vehicle ahead [s] (road)")
    min_gap: PosFloat = Field(2.0, description="standstill gap to the vehicle ahead [m] (road)")
    accel_max: PosFloat = Field(1.5, description="largest acceleration of the virtual car [m/s^2] (road)")
    decel_max: PosFloat = Field(3.0, description="comfortable deceleration of the virtual car [m/s^2] (road)")
    decel_emergency: PosFloat = Field(7.0, description="deceleration allowed to avoid a collision [m/s^2] (road)")
    jerk_max: PosFloat = Field(0.8, le=2.5, description=(
        "road: largest jerk of the longitudinal references outside emergencies [m/s^3] (the "
        "planner's bound, docs/model.md 'Smooth longitudinal references'); at most 2.5, ISO "
        "15622's comfort bound. Braking towards a request of more than 2 m/s^2 from a vehicle "
        "ahead sets in at jerk_brake instead"))
    jerk_brake: PosFloat = Field(2.0, le=2.5, description=(
        "road: largest jerk while the longitudinal references' braking grows towards a request of "
        "more than 2 m/s^2 from a vehicle ahead (braking firmly; the speed profile's own braking "
        "keeps jerk_max) [m/s^3]; at most 2.5, ISO 15622's "
        "comfort bound. Set it to jerk_max for one bound throughout (docs/model.md 'Smooth "
        "longitudinal references')"))
    bound_by_members: bool = Field(
        True, description="road: the virtual car's acceleration and its braking outside emergencies "
        "at most 90 % of the weakest member's speed law (a truck's Table 3.6 gains: 0.46 m/s^2); "
        "false: only accel_max and decel_max (the older behaviour)")
    emergency_release: bool = Field(
        True, description="road: braking harder than decel_max is released at 20 m/s^3 once the emergency "
        "is over; false: at the planner's 0.8 m/s^3 like any change (the older behaviour)")
    traffic_aware: bool = Field(
        True, description="road: the virtual car slows for vehicles ahead of the slots; false: it drives "
        "its speed profile whatever the traffic and the members do (every run of a scenario sees the same "
        "virtual car: a comparison of laws over the same head); the members still brake for what is ahead "
        "of them (their caps) and fall behind their slots, a head included (docs/platoon_laws.md)")
    accel_within_step: Literal["ramp", "hold"] = Field(
        "ramp", description="road: how the virtual car's acceleration and the members' acceleration caps, "
        "planned once per step, pass within the step: 'ramp' from the last step's value to this step's "
        "(continuous accelerations), 'hold' constant over the step (the older behaviour)")

    @field_validator("speed")
    @classmethod
    def _speed_nonneg(cls, v):
        vals = v.values if isinstance(v, ProfileSpec) else [v]
        if any(x < 0 for x in vals):
            raise ValueError("speed must be >= 0 m/s")
        return v


class MemberSpec(Strict):
    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$")
    offset: Pair | None = Field(None, description="[d_x, d_y] in the virtual car frame [m], eq 2.4")
    slot: SlotSpec | None = Field(None, description="slot in road coordinates (road scenarios)")
    position: Pair | None = Field(None, description="initial centre of gravity [x, y] [m]; on a road default: the slot")
    heading_deg: Finite | None = Field(None, description="initial heading [deg]; default the leader's")
    speed: NonNegFloat | None = Field(None, description="initial speed [m/s]; default the leader's")
    yaw_rate_deg_s: Finite = Field(0.0, description="initial yaw rate [deg/s] (dynamic model)")
    steer_deg: Finite = Field(0.0, description="initial steering angle [deg] (dynamic model)")
    preset: Literal["passenger_car", "small_truck"] | None = Field(
        None, description="per-member vehicle preset (mixed formations); default vehicle.preset")
    speed_gains: GAIN_TABLES | GainSpec | None = Field(None, description="per-member override of controller.speed_gains")
    yaw_gains: GAIN_TABLES | GainSpec | None = Field(None, description="per-member override of controller.yaw_gains")
    k: PosFloat | None = Field(None, description="per-member override of controller.k")
    k_theta: PosFloat | None = Field(None, description="per-member override of controller.k_theta")
    params: VehicleOverrides | None = Field(None, description="per-member override of vehicle.params "
                                            "(e.g. drive_lag_s), over its preset")

    @model_validator(mode="after")
    def _one_slot(self):
        if (self.offset is None) == (self.slot is None):
            raise ValueError("give exactly one of 'offset' (virtual car frame) or 'slot' (road frame)")
        return self
