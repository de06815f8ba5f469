"""The parts of a road run (sim/loop.py RunParts), assembled here as sim/loop.py
``free_space_run`` assembles a free-space run's: SUMO's world (sumo/world.py SumoWorld, or
sumo/driven.py's under SUMO's CACC), each formation's road reference generator (the governor's
limits, the jerk-limited planner, the maneuver planner when the scenario has maneuvers), the
watch of ramp traffic at the route's joins, the lane watch of platoon columns and the fleet of
all members, with each formation's departure and flow."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..scenario.schema import Scenario
from ..sumo.plan import RoadPlan
from ..sumo.world import SumoWorld

ADHESION_SHARE_COMFORT = 0.5
"""The virtual car's acceleration and comfortable deceleration are at most this share of mu g."""
ADHESION_SHARE_EMERGENCY = 0.8
"""Its emergency deceleration is at most this share of mu g (the members must be able to follow)."""


def road_run(sc: Scenario, plan: RoadPlan, rec, out_dir: Path, meta: dict,
             baseline: bool = False, step_hook=None, should_stop=None):
    """World, reference generators and fleet of a road run (loop.step_loop runs them)."""
    from ..sim.formation import Formation, join_configs, join_states, virtual_car_id
    from ..sim.loop import RunParts, one_formation
    from ..sim.road_load import road_load_part
    from ..sim.setup import build_fleet
    from ..sumo.driven import world_and_fleet

    parts = plan.formations or ((None, plan, slice(0, len(sc.members))),)
    views = [sc if setup is None else setup.view for setup, _, _ in parts]
    cfgs = [build_fleet(view) for view in views]
    fleet, world_class = world_and_fleet(sc, join_configs(cfgs), baseline)  # sumo_cacc: SUMO drives followers
    world = world_class(sc, plan, fleet, rec, out_dir, meta, baseline, step_hook)
    world.should_stop = should_stop
    watch_lanes(rec.incidents, sc, fleet, plan, baseline)  # lane departures of platoon columns
    built = [formation_parts(view, p, cfg, fleet.gains[rows], world, meta)
             for view, (_, p, rows), cfg in zip(views, parts, cfgs)]
    if plan.road.joins and not baseline:
        world.merges = merge_watch(sc, plan, parts, world, [getattr(gen, "merge_shift", None)
                                                             for gen, _, _ in built])
    meta["timing_s"] = {"sumo_step": 0.0, "sumo_read": 0.0, "sumo_place": 0.0,
                        "governor": 0.0, "control_model": 0.0, "record": 0.0}
    load = None if baseline else road_load_part(sc, plan.vehicles, plan.road, plan.road.line)
    if not plan.formations:  # one formation from t = 0
        from ..sumo.fused_path import fused_path
        gen, transforms, state = built[0]
        return one_formation(world, gen, fleet, state, transforms=transforms,
                             timing=meta["timing_s"], road_load=load, fused=fused_path)
    forms = []
    for (setup, _, rows), (gen, transforms, state) in zip(parts, built):
        waits = setup.depart > 0 or bool(setup.flow)
        forms.append(Formation(setup.id, rows, gen, transforms, virtual_car_id(setup.id, len(parts)),
                               depart=setup.depart, parked=gen.parked,
                               held=state.copy() if waits else None,
                               status="waiting" if waits else "running", flow=setup.flow))
    from ..sumo.fused_path import fused_path
    return RunParts(world, fleet, join_states([s for _, _, s in built]), forms,
                    timing=meta["timing_s"], road_load=load, fused=fused_path)


def merge_watch(sc: Scenario, plan: RoadPlan, parts, world: SumoWorld, shifts):
    """The run's watch of ramp traffic at the route's joins (sumo/merge_watch.py); ``shifts``:
    each formation's control/maneuvers/generator.py MergeShift (None: it does not shift)."""
    from run_contract.columns import DEFAULT_FORMATION_ID

    from ..control.merge import merge_params
    from ..sim.formation import virtual_car_id
    from ..sumo.merge_watch import MergeWatch, merge_sites

    groups = [(DEFAULT_FORMATION_ID if setup is None else setup.id,
               virtual_car_id(DEFAULT_FORMATION_ID if setup is None else setup.id, len(parts)),
               np.arange(rows.start, rows.stop)) for setup, _, rows in parts]
    return MergeWatch(merge_sites(plan.road), sc.cooperation.merge, merge_params(sc.cooperation, sc.leader.time_gap),
                      world, groups, float(sc.run.step), shifts)


def formation_parts(sc: Scenario, plan: RoadPlan, cfg, gains, world: SumoWorld, meta: dict):
    """(reference generator, transforms, initial state) of the formation ``sc`` sees, whose
    members are ``plan``'s (``gains``: their rows of sim/fleet.py Fleet.gains)."""
    from ..control.reference_road import GovernorLimits, RoadReference, SlotLayout, StepTiming
    from ..sim.fleet import initial_state
    from ..sim.column_gaps import column_gap_warnings
    from ..sim.setup import follow_limit, profile, road_mu, top_speed
    from ..sumo.plan import initial_targets

    run, ld, line = sc.run, sc.leader, plan.road.line
    n_ctrl = int(round(run.step / run.control_step))
    speed_profile = profile(ld.speed)
    # the virtual car never asks for more than the road's adhesion allows the members
    mu_g = road_mu(sc) * 9.81  # and never more than every member's speed law can follow
    follow = follow_limit(sc, gains, speed_profile, meta)
    limits = GovernorLimits(ld.time_gap, ld.min_gap,
                            min(ld.accel_max, ADHESION_SHARE_COMFORT * mu_g, follow),
                            min(ld.decel_max, ADHESION_SHARE_COMFORT * mu_g),
                            min(ld.decel_emergency, ADHESION_SHARE_EMERGENCY * mu_g), follow,
                            ld.traffic_aware)
    column_gap_warnings(sc, plan.slots, plan.is_road, plan.vehicles, gains, top_speed(sc, speed_profile),
                        limits.decel_emergency, meta)
    s0, v0 = float(sc.road.start), speed_profile(0.0)[0]
    tg0 = initial_targets(plan.road, plan.slots, plan.rigid, plan.is_road, s0, v0, 0.0)
    yaw0 = plan.speed0 * line.curvature(line.to_frenet(plan.pos0)[0])
    state = initial_state(cfg, plan.pos0, plan.heading0, plan.speed0, yaw0, np.zeros(cfg.n), tg0)
    # docs/model.md, "Accelerations within a step" and "Leave without stranding"
    ramp, release = sc.leader.accel_within_step == "ramp", sc.leader.emergency_release
    layout = SlotLayout(plan.slots, plan.rigid, plan.is_road,
                        np.array([v.width / 2 for v in plan.vehicles]),
                        np.array([v.cog_to_front_bumper for v in plan.vehicles]))
    args = (world.line.G, world.line.length, layout, s0, v0, speed_profile, limits,
            sc.road.end_margin, StepTiming(run.step / n_ctrl, n_ctrl, ramp, release,
                                            sc.leader.jerk_max, sc.leader.jerk_brake))
    shift = sc.cooperation.merge == "shift"  # moves away from merge lanes with the planner's lane change
    if not sc.maneuvers and not shift:
        return RoadReference(*args), [], state
    from ..control.maneuvers.generator import ManeuverRoadReference, PlanSlots
    from ..control.maneuvers.planner import ManeuverPlanner
    from ..sumo.road_setup import road_room
    lengths = np.array([v.length for v in plan.vehicles])
    widths = np.array([v.width for v in plan.vehicles])
    planner = ManeuverPlanner(sc.maneuvers, plan.slots, plan.road.lanes, sc.maneuver_limits,
                              lengths, widths, list(plan.ids or world.ids), road_room(plan.road),
                              (ld.time_gap, ld.min_gap),
                              np.array([v.cog_to_front_bumper for v in plan.vehicles]))
    gen = ManeuverRoadReference(*args, planner=planner, length=lengths, merge_shift=shift)
    return gen, [PlanSlots(planner)], state


def watch_lanes(incidents, sc, fleet, plan, baseline: bool) -> None:
    """sim/incidents.py lane departures of the road run's platoon-law columns (every member of
    a column under a platoon law of ours or SUMO's CACC, the head included; runs without
    maneuvers, which move slots): more than half the reference lane's width across from the
    slot's lateral offset."""
    if incidents is None or baseline or _has_maneuvers(sc):
        return
    platoon = (np.asarray(fleet.base_law) > 0) | (sc.controller.law == "sumo_cacc")
    slot_d = np.where(plan.is_road, plan.slots[:, 1], plan.rigid[:, 1])
    incidents.watch_lanes(platoon & plan.is_road, slot_d, 0.5 * plan.road.lane_width)


def _has_maneuvers(sc) -> bool:
    """Does any formation of the scenario run maneuvers?"""
    return bool(sc.maneuvers) or any(f.maneuvers for f in getattr(sc, "formations", []) or [])
