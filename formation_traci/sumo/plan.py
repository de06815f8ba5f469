"""Everything a road run prepares and checks before SUMO starts: the road, the slots,
the members' initial poses, SUMO's command line and the members' vehicle type."""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..control.formation import Targets, rigid_targets
from ..models.params import VehicleParams
from ..road.leader import road_leader_state
from ..road.targets import road_targets
from ..scenario.formations import formation_setups
from ..scenario.load import ScenarioError
from ..scenario.schema import Scenario
from ..sim.column_gaps import check_column_bodies
from .messages import SUMO_ARGS as SUMO_QUIET
from .road_setup import (Road, build_road, check_no_overlap, check_positions, check_route_ends, check_slots,
                         initial_check_limit, rectangles_overlap, slot_offsets)
from ..sim.setup import member_vehicles, profile, vehicle_params
from .formation_flows import expand_flows
from .ssm import ssm_args
from .adapter import MemberType
from .options import check_options, place_outputs

MEMBER_ROUTE = "formation_route"


INSERT_CLEAR_TIME = 1.0
"""Free space kept behind every member when it is inserted, as time at its speed [s]."""


@dataclass(frozen=True)
class RoadPlan:
    """Everything prepared and checked before SUMO starts: every member of every formation
    (rows in formation order), and each formation's own plan (``formations``)."""

    road: Road
    veh: VehicleParams  # vehicle.preset's chassis (the scenario's default)
    slots: np.ndarray  # (n, 2) road-frame (along, across) [m]; NaN rows for rigid members
    rigid: np.ndarray  # (n, 2) virtual-car-frame offsets [m]; NaN rows for road members
    is_road: np.ndarray  # (n,) bool
    pos0: np.ndarray  # (n, 2) initial CoG [m]
    heading0: np.ndarray  # (n,) [rad]
    speed0: np.ndarray  # (n,) [m/s]
    vehicles: tuple[VehicleParams, ...] = ()  # every member's chassis (members.preset)
    ids: tuple[str, ...] = ()  # every member's id
    presets: tuple[str | None, ...] = ()  # every member's own preset (None: vehicle.preset)
    formations: tuple = ()  # (FormationSetup, its RoadPlan, its rows: slice) of each formation
    scenario: Scenario | None = None  # the scenario with its formation flows' formations (sumo/formation_flows.py)
    flow_keep: dict | None = None  # traffic flow id -> the share of its demand it keeps (penetration)
    flow_share_of: dict | None = None  # formation flow id -> the traffic flow it is a share of, or ''; None: no formation flow


def prepare(sc: Scenario, source: Path | None) -> RoadPlan:
    """Resolve and check the road and the formations; raises ScenarioError before anything runs."""
    road = build_road(sc, source)
    check_options(list(sc.sumo.options), source)
    run_sc, flow_of, keep, share_of = expand_flows(sc, {f: lanes for f, (_, lanes) in road.flow_routes.items()}, source)
    parts, at = [], 0
    for setup in formation_setups(run_sc, flow_of):
        plan = _named_fields(setup.field, source, lambda: _formation_plan(setup, road, source))
        parts.append((setup, plan, slice(at, at + len(plan.ids))))
        at += len(plan.ids)
    if len(parts) == 1 and not parts[0][0].depart and run_sc.members:  # the top-level formation alone
        return parts[0][1]
    _check_apart([p for p in parts if not p[0].flow], source)
    cat = (lambda name: np.concatenate([getattr(p, name) for _, p, _ in parts]))  # noqa: E731
    return RoadPlan(road, parts[0][1].veh, cat("slots"), cat("rigid"), cat("is_road"), cat("pos0"),
                    cat("heading0"), cat("speed0"), sum((p.vehicles for _, p, _ in parts), ()),
                    sum((p.ids for _, p, _ in parts), ()), sum((p.presets for _, p, _ in parts), ()),
                    tuple(parts), run_sc, keep if share_of else None, share_of or None)


def _formation_plan(setup, road: Road, source) -> RoadPlan:
    """One formation's plan (``setup.view`` is the scenario it sees)."""
    sc = setup.view
    veh = vehicle_params(sc)
    slots = slot_offsets(sc, road, setup.lane_shift)
    vehicles = member_vehicles(sc)
    is_road = np.array([m.slot is not None for m in sc.members])
    rigid = np.array([m.offset if m.offset is not None else [np.nan, np.nan] for m in sc.members], float)
    check_route_ends(sc, road, np.where(is_road, slots[:, 0], rigid[:, 0]), vehicles, source)
    check_slots(sc, road, slots, vehicles, source, s_max=initial_check_limit(sc))
    v0, v0_dot = profile(sc.leader.speed)(0.0)
    tg = initial_targets(road, slots, rigid, is_road, sc.road.start, v0, 0.0)
    pos0 = tg.p.copy()
    heading0 = np.array([math.atan2(y, x) for x, y in tg.v.tolist()])  # libm, not numpy's SIMD loop
    speed0 = np.hypot(tg.v[:, 0], tg.v[:, 1])
    for i, m in enumerate(sc.members):
        if m.position is not None:
            pos0[i] = m.position
            heading0[i] = float(road.line.heading(road.line.to_frenet(np.asarray([m.position]))[0][0]))
        if m.heading_deg is not None:
            heading0[i] = math.radians(m.heading_deg)
        if m.speed is not None:
            speed0[i] = m.speed
    check_positions(sc, road, pos0, source)
    check_no_overlap(sc, pos0, heading0, vehicles, source)
    check_column_bodies(sc, slots, is_road, vehicles, source)  # members placed off their slots too
    return RoadPlan(road, veh, slots, rigid, is_road, pos0, heading0, speed0, tuple(vehicles),
                    tuple(m.id for m in sc.members), tuple(m.preset for m in sc.members))


def _named_fields(prefix: str, source, build):
    """``build()``, its ScenarioError's fields given as the formation's (``prefix``:
    'formations.<j>.'; road.start is the formation's ``start``)."""
    try:
        return build()
    except ScenarioError as exc:
        if not prefix:
            raise
        fields = [(prefix + ("start" if f == "road.start" else f), msg) for f, msg in exc.problems]
        raise ScenarioError(source or "<scenario>", fields) from None


def _check_apart(parts, source) -> None:
    """Members of formations that enter at the same time must not overlap there."""
    problems = []
    for (sa, pa, _), (sb, pb, _) in itertools.combinations(parts, 2):
        if sa.depart != sb.depart:
            continue
        for i, j in itertools.product(range(len(pa.ids)), range(len(pb.ids))):
            va, vb = pa.vehicles[i], pb.vehicles[j]
            if rectangles_overlap(pa.pos0[i], pa.heading0[i], pb.pos0[j], pb.heading0[j],
                                  va.length, va.width, vb.length, vb.width):
                problems.append((f"{sb.field}members.{j}", (
                    f"member {pb.ids[j]!r} of formation {sb.id!r} would enter on top of {pa.ids[i]!r} "
                    f"of formation {sa.id!r} at t = {sa.depart:g} s (their bodies overlap)")))
    if problems:
        raise ScenarioError(source or "<scenario>", problems)


def initial_targets(road: Road, slots, rigid, is_road, s, v, a) -> Targets:
    """Desired points of all members at virtual-car arc length s [m], speed v, acceleration a."""
    if is_road.all():
        return road_targets(road.line, s, v, a, slots)
    vc = road_leader_state(road.line, s, v, a)
    rt = rigid_targets(vc, np.nan_to_num(rigid))
    if not is_road.any():
        return rt
    tr = road_targets(road.line, s, v, a, np.nan_to_num(slots))
    m = is_road[:, None]
    return Targets(np.where(m, tr.p, rt.p), np.where(m, tr.v, rt.v), np.where(m, tr.a, rt.a))


def sumo_args(sc: Scenario, net: Path, routes: Path, sumo_dir: Path, t_end: float,
              member_ids=None) -> list[str]:
    """SUMO's command line; ``member_ids``: every member (default: the top-level formation's)."""
    member_ids = [m.id for m in sc.members] if member_ids is None else member_ids
    args = ["-n", str(net), "-r", str(routes), "--step-length", repr(sc.run.step),
            "--begin", "0", "--end", repr(t_end), "--seed", str(sc.run.seed),
            "--lateral-resolution", repr(sc.sumo.lateral_resolution),
            "--collision.action", "warn", "--collision.mingap-factor", "0",
            "--collision.check-junctions", "true",
            "--no-step-log", "true", "--log", str(sumo_dir / "sumo.log"),
            "--error-log", str(sumo_dir / "messages.log"), *SUMO_QUIET,
            "--duration-log.disable", "true"]
    args += ssm_args(sc.sumo.ssm, list(member_ids), sumo_dir / "ssm.xml")
    if sc.sumo.friction_device:
        args += ["--device.friction.probability", "1", "--device.friction.stdDev", "0"]
    if sc.sumo.fcd:
        args += ["--fcd-output", str(sumo_dir / "fcd.parquet")]
    if sc.sumo.gui and sc.sumo.backend == "traci":  # run at once, close at the end
        args += [o for o in ("--start", "--quit-on-end") if o not in sc.sumo.options]
    return args + place_outputs(list(sc.sumo.options), sumo_dir)


def member_type(sc: Scenario, veh: VehicleParams, preset: str | None = None) -> MemberType:
    """SUMO vType of members with chassis ``veh`` of ``preset`` (default vehicle.preset)."""
    preset = preset or sc.vehicle.preset
    return MemberType(id=f"member_{preset}", length=veh.length, width=veh.width,
                      d_front=veh.cog_to_front_bumper, color=veh.color,
                      vclass=MEMBER_VCLASS[preset],
                      ssm_device=sc.sumo.ssm == "members" and sc.sumo.attach_port is None)


MEMBER_VCLASS = {"passenger_car": "custom1", "small_truck": "custom2"}
"""Members' own SUMO vehicle classes: lane permissions can keep them (only) off the internal
lanes where the network's connections cross its lane geometry (road/lanes.py)."""


def member_types(sc: Scenario, plan: RoadPlan) -> list[MemberType]:
    """Every member's SUMO vType (its own preset in a mixed formation)."""
    return [member_type(sc, veh, preset) for veh, preset in zip(plan.vehicles, plan.presets)]
