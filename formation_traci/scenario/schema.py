"""Scenario schema: a TOML document validated into frozen, typed objects.

Every table forbids unknown keys; defaults live here and nowhere else. Field units are in
the names (``_deg``, ``_deg_s``) or in the field descriptions (SI otherwise).
See docs/scenarios.md for the field-by-field reference.
"""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from ..control.laws import DEFAULT_LAW, SUMO_LAWS, law_names
from ..record.columns import DEFAULT_FORMATION_ID

from .base import Finite, NonNegFloat, Pair, PosFloat, ProfileSpec, Signal, Strict  # noqa: F401
from .comm_spec import CommLinkSpec, CommSpec  # noqa: F401
from .law_specs import AccSpec, CaccPathSpec, CaccPloegSpec, SumoCaccSpec, sumo_cacc_rules  # noqa: F401
from .maneuvers import ManeuverLimits, ManeuverSpec, SlotSpec
from .road_traffic import FlowSpec, RoadSpec, RouteEnds, RouteValue, TrafficSpec  # noqa: F401 (re-exported)


class RunSpec(Strict):
    duration: PosFloat = Field(description="simulated time [s]")
    step: PosFloat = Field(0.05, description="outer step: recording interval and SUMO step length [s]")
    control_step: PosFloat = Field(0.01, description="controller sampling period [s]; divides step")
    physics_step: PosFloat = Field(0.01, le=0.01, description="largest RK4 sub-step [s]; at most 0.01")
    seed: int = Field(0, ge=0, description="random seed (SUMO's --seed; recorded in run.json)")
    independent_members: bool = Field(
        False, description="free space: the members are independent experiments overlaid in one run "
        "(gain studies): their bodies overlapping is no member collision (ignored on a road)")

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
    acc: AccSpec = AccSpec()
    cacc_path: CaccPathSpec = CaccPathSpec()
    cacc_ploeg: CaccPloegSpec = CaccPloegSpec()
    sumo_cacc: SumoCaccSpec = SumoCaccSpec()
    k: PosFloat = Field(1.0, description="position gain of (2.7) [m/s]")
    k_theta: PosFloat = Field(3.0, description="heading gain of (2.8) [1/s]")
    speed_gains: GAIN_TABLES | GainSpec = Field(
        "table_3_4", description="linear-velocity schedule (3.34); 'table_3_6' for the truck")
    yaw_gains: GAIN_TABLES | GainSpec = Field("table_3_8", description="angular-velocity schedule (3.34)")

    @field_validator("law")
    @classmethod
    def _known_law(cls, v):
        if v not in law_names() + SUMO_LAWS:
            raise ValueError(f"unknown control law {v!r}; expected one of: "
                             f"{', '.join(law_names() + SUMO_LAWS)}")
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
    bound_by_members: bool = Field(
        True, description="road: the virtual car's acceleration and its braking outside emergencies "
        "at most 90 % of the weakest member's speed law (a truck's Table 3.6 gains: 0.46 m/s^2; issue 32); "
        "false: only accel_max and decel_max (before issue 32)")
    emergency_release: bool = Field(
        True, description="road: braking harder than decel_max is released at 20 m/s^3 once the emergency "
        "is over (issue 32); false: at the planner's 0.8 m/s^3 like any change (before issue 32)")
    accel_within_step: Literal["ramp", "hold"] = Field(
        "ramp", description="road: how the virtual car's acceleration and the members' acceleration caps, "
        "planned once per step, pass within the step: 'ramp' from the last step's value to this step's "
        "(continuous accelerations, issue 32), 'hold' constant over the step (before issue 32)")

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


class FormationSpec(Strict):
    """A further formation of the run (free space): its own virtual leader, members and
    controller; the top-level ``leader``/``members``/``controller``/``comm`` are the first."""

    id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$", description="formation_id in the tables")
    leader: LeaderSpec
    members: list[MemberSpec] = Field(min_length=1, description="at least one member")
    controller: ControllerSpec = ControllerSpec()
    comm: CommSpec | None = Field(None, description="leader-to-member radio; default: perfect")


class SumoSpec(Strict):
    backend: Literal["libsumo", "traci"] = "libsumo"
    gui: bool = Field(False, description="run sumo-gui (traci backend only)")
    lateral_resolution: PosFloat = Field(0.8, description="sublane width [m] (--lateral-resolution)")
    ssm: Literal["members", "all", "off"] = Field(
        "members", description="SUMO's SSM device (TTC, DRAC, PET): on the formation members only "
        "(default; background pairs are measured from the recording by the analysis), on every "
        "vehicle (about 10x the cost of the run), or off; true/false mean \"all\"/\"off\"")
    fcd: bool = Field(False, description="also write SUMO's FCD output (Parquet)")
    fcd_frame: Literal["sumo", "formation"] = Field(
        "sumo", description="FCD in SUMO's frame (SUMO time, front bumper, deg CW from north) or the "
                            "formation's (t = SUMO time - warm-up, centre of gravity, rad CCW from +x)")
    friction_device: bool = Field(True, description="SUMO's cars slow down on low-friction lanes (device.friction)")
    options: list[str] = Field(default_factory=list, description="extra SUMO command-line options")
    attach_port: int | None = Field(None, ge=1, le=65535, description="attach (traci) to a SUMO already "
                                    "running with --remote-port PORT instead of starting one")

    @field_validator("ssm", mode="before")
    @classmethod
    def _ssm_bool(cls, v):
        if isinstance(v, bool):  # the earlier boolean form: true was every vehicle
            return "all" if v else "off"
        return v

    @model_validator(mode="after")
    def _attach(self):
        if self.attach_port is not None and self.backend != "traci":
            raise ValueError("attach_port needs backend = \"traci\"")
        return self


class EnergySpec(Strict):
    """Driving resistances and the formation's drag (docs/energy.md)."""

    resistances: bool = Field(False, description="rolling (eq 3.15), aerodynamic and grade resistance "
                              "on; false: the seed's model, which drives against none")
    drag_interaction: bool = Field(True, description="lower each member's drag for the vehicles "
                                   "ahead of and behind it (needs resistances)")
    air_density: PosFloat = Field(1.225, le=2.0, description="air density [kg/m^3] (ISO 2533 sea level)")


class OpenLoopSpec(Strict):
    """Every member driven by input profiles or by one of its loops alone (seed 3.1.6-3.2.2).

    Longitudinal: ``accel`` (desired acceleration a_r) or ``speed_ref`` (the speed loop,
    3.32-3.34, with controller.speed_gains or a plain P gain per member). Lateral: ``steer_deg``
    (the wheel angle set directly), ``steer_rate_deg_s`` (3.38), or ``yaw_rate_ref_deg_s`` (the
    yaw-rate loop with controller.yaw_gains: steering rate 3.37, or angle 3.35 per member).
    The formation controller and the virtual car are not used (members' offsets are ignored).
    """

    accel: Signal | None = Field(None, description="desired acceleration a_r [m/s^2]")
    speed_ref: Signal | None = Field(None, description="speed reference of the speed loop [m/s]")
    speed_p_gain: dict[str, PosFloat] = Field(default_factory=dict, description=(
        "member id -> plain P gain K_p^lin of (3.32) [1/s]; other members use the schedule"))
    steer_deg: Signal | None = Field(None, description="front wheel steering angle [deg]")
    steer_rate_deg_s: Signal | None = Field(None, description="steering rate [deg/s]")
    yaw_rate_ref_deg_s: Signal | None = Field(None, description="yaw-rate reference of the yaw loop [deg/s]")
    yaw_input: dict[str, Literal["steer_rate", "steer_angle"]] = Field(default_factory=dict, description=(
        "member id -> the yaw loop's output: 'steer_rate' (3.37, default) or 'steer_angle' (3.35)"))
    linear_speed: PosFloat | None = Field(None, description=(
        "also run the linear model (3.30) linearised at this speed [m/s] beside each member"))

    @model_validator(mode="after")
    def _one_each(self):
        if (self.accel is None) == (self.speed_ref is None):
            raise ValueError("give exactly one of 'accel' or 'speed_ref'")
        lat = [self.steer_deg, self.steer_rate_deg_s, self.yaw_rate_ref_deg_s]
        if sum(x is not None for x in lat) != 1:
            raise ValueError("give exactly one of 'steer_deg', 'steer_rate_deg_s' or 'yaw_rate_ref_deg_s'")
        return self


class Scenario(Strict):
    name: str = ""
    description: str = ""
    run: RunSpec
    vehicle: VehicleSpec = VehicleSpec()
    controller: ControllerSpec = ControllerSpec()
    leader: LeaderSpec
    members: list[MemberSpec] = Field(min_length=1, description="at least one member")
    road: RoadSpec | None = Field(None, description="SUMO road; without it the run is in free space")
    traffic: TrafficSpec = TrafficSpec()
    sumo: SumoSpec = SumoSpec()
    energy: EnergySpec = EnergySpec()
    comm: CommSpec | None = Field(None, description="leader-to-member radio; default: perfect")
    open_loop: OpenLoopSpec | None = Field(None, description="drive the members open loop (free space only)")
    maneuvers: list[ManeuverSpec] = Field(default_factory=list, description="scheduled maneuvers, run one at a time in this order")
    maneuver_limits: ManeuverLimits = ManeuverLimits()
    formations: list[FormationSpec] = Field(
        default_factory=list, description="further formations beside the top-level one (whose "
        f"formation_id is '{DEFAULT_FORMATION_ID}'); free space only for now")

    @model_validator(mode="after")
    def _formation_rules(self):
        if not self.formations:
            return self
        if self.road is not None or self.open_loop is not None:
            raise ValueError("formations: several formations run in free space (no [road], no "
                             "open_loop) in this version")
        fids = [DEFAULT_FORMATION_ID] + [f.id for f in self.formations]
        if len(set(fids)) < len(fids):
            raise ValueError(f"formations: ids must be unique and not '{DEFAULT_FORMATION_ID}' "
                             f"(the top-level formation's): {fids}")
        ids = [m.id for m in self.members] + [m.id for f in self.formations for m in f.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"member ids must be unique over all formations, repeated: {dup}")
        for j, f in enumerate(self.formations):
            if any(m.offset is None or m.position is None for m in f.members):
                raise ValueError(f"formations.{j}: free space needs 'offset' and 'position' for every member")
            if f.comm is not None and set(f.comm.links) - {m.id for m in f.members}:
                raise ValueError(f"formations.{j}.comm.links names members not in the formation")
        return self

    @model_validator(mode="after")
    def _energy_needs_forces(self):
        if self.energy.resistances and self.vehicle.model != "dynamic":
            raise ValueError("energy.resistances needs vehicle.model = \"dynamic\" "
                             "(the kinematic model has no forces)")
        return self

    @model_validator(mode="after")
    def _comm_rules(self):
        c = self.comm
        if c is None:
            return self
        if c.beacon_hz is not None and c.beacon_hz * self.run.control_step > 1.0 + 1e-9:
            raise ValueError(f"comm.beacon_hz ({c.beacon_hz} Hz) must not exceed the control rate "
                             f"(1 / run.control_step = {1.0 / self.run.control_step:g} Hz)")
        ids = {m.id for m in self.members}
        bad = sorted(set(c.links) - ids)
        if bad:
            raise ValueError(f"comm.links names members that do not exist: {bad}")
        return self

    @model_validator(mode="after")
    def _maneuver_rules(self):
        if not self.maneuvers:
            return self
        if self.road is None:
            raise ValueError("maneuvers need a [road] table")
        if any(m.slot is None for m in self.members):
            raise ValueError("maneuvers need road-frame slots ('slot') for every member")
        for i, mv in enumerate(self.maneuvers):
            if mv.slots is not None and len(mv.slots) < len(self.members):
                raise ValueError(f"maneuvers.{i}.slots: {len(mv.slots)} slots for {len(self.members)} members")
            if mv.member is not None and mv.member not in [m.id for m in self.members]:
                raise ValueError(f"maneuvers.{i}.member: no member {mv.member!r}")
        joins = [mv.member for mv in self.maneuvers if mv.kind == "join"]
        if len(set(joins)) < len(joins) or len(joins) >= len(self.members):
            raise ValueError("maneuvers: a member joins at most once, and at least one member "
                             "must be in the formation from the start")
        return self

    @model_validator(mode="after")
    def _world_rules(self):
        if self.open_loop is not None:
            if self.road is not None or self.vehicle.model != "dynamic":
                raise ValueError("open_loop needs free space (no [road]) and vehicle.model = \"dynamic\"")
            ids = {m.id for m in self.members}
            bad = sorted((set(self.open_loop.speed_p_gain) | set(self.open_loop.yaw_input)) - ids)
            if bad:
                raise ValueError(f"open_loop names members that do not exist: {bad}")
        if self.road is None:
            bad = [f"members.{i}" for i, m in enumerate(self.members) if m.slot is not None or m.position is None]
            if bad:
                raise ValueError(f"free-space scenarios need 'offset' and 'position' for every member ({', '.join(bad)}); "
                                 "road slots need a [road] table")
            if self.traffic.flows:
                raise ValueError("traffic flows need a [road] table")
        else:
            if self.leader.yaw_rate_deg_s != 0.0:
                raise ValueError("on a road the virtual car's yaw rate comes from the road: remove leader.yaw_rate_deg_s")
        if self.sumo.attach_port is not None and self.traffic.flows:
            raise ValueError("with sumo.attach_port the traffic comes from the running SUMO: remove traffic.flows")
        ids = [f.id for f in self.traffic.flows]
        if len(set(ids)) != len(ids):
            raise ValueError("flow ids must be unique")
        return self

    @model_validator(mode="after")
    def _sumo_cacc(self):
        return sumo_cacc_rules(self)

    @model_validator(mode="after")
    def _unique_ids(self):
        ids = [m.id for m in self.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"member ids must be unique, repeated: {dup}")
        if "vc" in ids:
            raise ValueError("member id 'vc' is reserved for the virtual car")
        return self
