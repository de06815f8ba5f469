"""Scenario schema: a TOML document validated into frozen, typed objects.

Every table forbids unknown keys; defaults live here and nowhere else. Field units are in
the names (``_deg``, ``_deg_s``) or in the field descriptions (SI otherwise).
See docs/scenarios.md for the field-by-field reference.
"""
from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from run_contract.columns import DEFAULT_FORMATION_ID

from ..control.laws import sumo_cacc
from .base import Finite, NonNegFloat, Pair, PosFloat, ProfileSpec, Signal, Strict  # noqa: F401
from .comm_spec import CommLinkSpec, CommSpec  # noqa: F401
from .cooperation import CooperationSpec
from .formation_parts import (GAIN_TABLES, SURFACE_NAMES, ControllerSpec, GainSpec,  # noqa: F401 (re-exported)
                              LeaderSpec, MemberSpec, VehicleOverrides, VehicleSpec)
from .formation_spec import FormationFlowSpec, FormationSpec, FormationTemplate, formation_fits  # noqa: F401
from .maneuvers import ManeuverLimits, ManeuverSpec, SlotSpec  # noqa: F401 (re-exported)
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
    members: list[MemberSpec] = Field(
        default_factory=list, description="the top-level formation's members (at least one), or none when "
        "[[formations]] or [[formation_flows]] are the run's formations")
    road: RoadSpec | None = Field(None, description="SUMO road; without it the run is in free space")
    traffic: TrafficSpec = TrafficSpec()
    sumo: SumoSpec = SumoSpec()
    energy: EnergySpec = EnergySpec()
    comm: CommSpec | None = Field(None, description="leader-to-member radio; default: perfect")
    cooperation: CooperationSpec = CooperationSpec()
    open_loop: OpenLoopSpec | None = Field(None, description="drive the members open loop (free space only)")
    maneuvers: list[ManeuverSpec] = Field(default_factory=list, description="scheduled maneuvers, run one at a time in this order")
    maneuver_limits: ManeuverLimits = ManeuverLimits()
    formations: list[FormationSpec] = Field(
        default_factory=list, description="further formations beside the top-level one (whose "
        f"formation_id is '{DEFAULT_FORMATION_ID}')")
    depart: NonNegFloat = Field(0.0, description="road: when the top-level formation's members enter the "
                                "road [s] (run time; a formation flow's study may keep it out of the run)")
    formation_flows: list[FormationFlowSpec] = Field(
        default_factory=list, description="formations inserted while the run goes (road)")

    @model_validator(mode="before")
    @classmethod
    def _leader_of_formations(cls, data):
        """No top-level formation: [leader] may be left out; the first formation's (or
        formation flow's) leader is then the run's (its set speed sizes the measured stretch)."""
        if not isinstance(data, dict) or data.get("members") or "leader" in data:
            return data
        for f in data.get("formations") or []:
            if isinstance(f, dict) and "leader" in f:
                return {**data, "leader": f["leader"]}
        for f in data.get("formation_flows") or []:
            if isinstance(f, dict) and isinstance(f.get("formation"), dict) and "leader" in f["formation"]:
                return {**data, "leader": f["formation"]["leader"]}
        return data

    @model_validator(mode="after")
    def _cooperation_on_a_road(self):
        if self.road is None and self.cooperation != CooperationSpec():  # the default is echoed in run.json
            raise ValueError("cooperation: needs a [road] (ramp traffic is SUMO's)")
        if self.cooperation.merge == "shift":  # the maneuver planner's lane change moves the slots
            members = list(self.members) + [m for f in self.formations for m in f.members] + [
                m for f in self.formation_flows for m in f.formation.members]
            if any(m.slot is None for m in members):
                raise ValueError("cooperation.merge = \"shift\" needs road-frame slots ('slot') for every member "
                                 "(the whole formation changes lanes)")
            if self.controller.law == "sumo_cacc":
                raise ValueError("cooperation.merge = \"shift\" is not supported with controller.law = "
                                 "\"sumo_cacc\" (SUMO's CACC keeps its lane)")
        return self

    @model_validator(mode="after")
    def _top_level_formation(self):
        if self.members:
            return self
        if not self.formations and not self.formation_flows:
            raise ValueError("members: at least one member, unless [[formations]] or [[formation_flows]] "
                             "give the run's formations")
        for name, given in (("maneuvers", self.maneuvers), ("depart", self.depart),
                            ("open_loop", self.open_loop), ("comm", self.comm)):
            if given:
                raise ValueError(f"{name}: belongs to the top-level formation, which has no members "
                                 "(give it in the formation's own table)")
        return self

    @model_validator(mode="after")
    def _depart_on_road(self):
        if self.depart and self.road is None:
            raise ValueError("depart: the top-level formation departs later only on a [road]")
        return self

    @model_validator(mode="after")
    def _flow_rules(self):
        if not self.formation_flows:
            return self
        if self.road is None:
            raise ValueError("formation_flows: formations are inserted on a [road]")
        if any(mv.kind == "join" for mv in self.maneuvers):
            raise ValueError("maneuvers: a join runs in a scenario of one formation only")
        ids = [f.id for f in self.formation_flows]
        if len(set(ids)) < len(ids) or set(ids) & {f.id for f in self.formations}:
            raise ValueError(f"formation_flows: ids must be unique and differ from the formations' ids: {ids}")
        flows = {f.id for f in self.traffic.flows}
        for j, f in enumerate(self.formation_flows):
            if f.of_flow is not None and f.of_flow not in flows:
                raise ValueError(f"formation_flows.{j}.of_flow: expected one of the traffic.flows ids "
                                 f"{sorted(flows)}, got {f.of_flow!r}")
        return self

    @model_validator(mode="after")
    def _formation_rules(self):
        if not self.formations:
            return self
        if self.open_loop is not None:
            raise ValueError("formations: several formations do not run open loop")
        fids = [DEFAULT_FORMATION_ID] + [f.id for f in self.formations]
        if len(set(fids)) < len(fids):
            raise ValueError(f"formations: ids must be unique and not '{DEFAULT_FORMATION_ID}' "
                             f"(the top-level formation's): {fids}")
        ids = [m.id for m in self.members] + [m.id for f in self.formations for m in f.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"member ids must be unique over all formations, repeated: {dup}")
        for j, f in enumerate(self.formations):
            formation_fits(j, f, self.road is not None)
        joins = [mv for mv in self.maneuvers if mv.kind == "join"] + [
            mv for f in self.formations for mv in f.maneuvers if mv.kind == "join"]
        if self.road is not None and joins:
            raise ValueError("maneuvers: a join runs in a scenario of one formation only (it would have "
                             "to tell the other formations' members from SUMO's vehicles)")
        return self

    @model_validator(mode="after")
    def _sumo_cacc(self):
        laws = [f.controller.law for f in self.formations] + [f.formation.controller.law for f in self.formation_flows]
        if "sumo_cacc" in laws or (self.controller.law == "sumo_cacc" and (self.formations or self.formation_flows)):
            raise ValueError("controller.law = \"sumo_cacc\" runs in a scenario of one formation only")
        return sumo_cacc.check_scenario(self)

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
            if self.vehicle.variant is not None:
                raise ValueError("open_loop integrates the dynamic model itself: no vehicle.variant")
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
    def _unique_ids(self):
        ids = [m.id for m in self.members]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"member ids must be unique, repeated: {dup}")
        if "vc" in ids:
            raise ValueError("member id 'vc' is reserved for the virtual car")
        return self
