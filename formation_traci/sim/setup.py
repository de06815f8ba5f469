"""Turn a validated Scenario into the runtime objects: parameters, fleet, leader."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..control.formation import LeaderState, rigid_targets
from ..control.laws import PLATOON_LAWS, SUMO_LAWS, sumo_law
from ..control.schedule import FOLLOW_SHARE, GAIN_PRESETS, GainSchedule, law_peak
from ..control.virtual_car import FreeLeader, Profile
from ..models.linear import stable_blend_speed
from ..models.params import (LOW_SPEED_DEFAULT, SURFACES, VEHICLE_PRESETS, VehicleParams,
                             bicycle_params, make_tires, stack)
from ..comm.channel import build_channel, link_params
from ..comm.link import CommChannel
from ..scenario.formations import formation_views
from ..scenario.schema import GainSpec, ProfileSpec, Scenario
from .fleet import FleetConfig, FleetState, initial_state
from .fleet_models import variant_params


def road_mu(sc: Scenario) -> float:
    """Road adhesion [-]: vehicle.mu if given, else Table 3.3 for vehicle.surface."""
    return sc.vehicle.mu if sc.vehicle.mu is not None else SURFACES[sc.vehicle.surface]


def vehicle_params(sc: Scenario, preset: str | None = None, own=None) -> VehicleParams:
    """The preset chassis (``preset``, default vehicle.preset) with the scenario's
    vehicle.params overrides applied, then a member's own ``params`` (``own``)."""
    veh = _overridden(VEHICLE_PRESETS[preset or sc.vehicle.preset], sc.vehicle.params)
    return veh if own is None else _overridden(veh, own)


def _overridden(veh: VehicleParams, o) -> VehicleParams:
    """``veh`` with the values a VehicleOverrides table gives."""
    changes = {k: v for k, v in o.model_dump().items()
               if v is not None and k not in ("steer_max_deg", "steer_rate_max_deg_s")}
    if o.steer_max_deg is not None:
        changes["steer_max"] = float(np.deg2rad(o.steer_max_deg))
    if o.steer_rate_max_deg_s is not None:
        changes["steer_rate_max"] = float(np.deg2rad(o.steer_rate_max_deg_s))
    return replace(veh, **changes)


def member_vehicles(sc: Scenario) -> list[VehicleParams]:
    """Every member's chassis: its own preset (members.preset) or vehicle.preset."""
    return [vehicle_params(sc, m.preset, m.params) for m in sc.members]


def _member_gains(sc: Scenario, name: str):
    """One GainSchedule, or one per member when any member overrides ``name``."""
    default = getattr(sc.controller, name)
    own = [getattr(m, name) for m in sc.members]
    if all(g is None for g in own):
        return gain_schedule(default)
    return tuple(gain_schedule(g if g is not None else default) for g in own)


def gain_schedule(spec: str | GainSpec) -> GainSchedule:
    if isinstance(spec, str):
        return GAIN_PRESETS[spec]
    return GainSchedule(spec.g_min, spec.g_max, spec.k_min)


def profile(spec, scale: float = 1.0) -> Profile:
    """A scenario signal (constant or ProfileSpec) as a Profile, values times ``scale``."""
    if isinstance(spec, ProfileSpec):
        return Profile(tuple(spec.t), tuple(v * scale for v in spec.values), spec.interp)
    return Profile.constant(spec * scale)


def top_speed(sc: Scenario, speed_profile: Profile) -> float:
    """The leader's highest speed [m/s] over the run (its profile every 0.05 s)."""
    t = np.arange(0.0, sc.run.duration + 1e-9, 0.05)
    return max(float(speed_profile(float(ti))[0]) for ti in t)


def follow_limit(sc: Scenario, gains: np.ndarray, speed_profile: Profile, meta: dict) -> float:
    """The largest acceleration and braking [m/s^2] the virtual car may ask of every member on a
    road: FOLLOW_SHARE of the smallest peak of the members' speed laws (control/schedule.py
    law_peak; ``gains`` (n, 6) as sim/fleet.py Fleet.gains; inf for the kinematic model, which
    has no speed loop). When the leader's speed profile asks more, a warning goes to stderr
    and run.json ``warnings``: the virtual car follows the profile more slowly (with
    ``leader.bound_by_members = false`` it does not: inf, the warning says the formation may not
    hold)."""
    if sc.vehicle.model != "dynamic":
        return float("inf")
    peaks = [law_peak(*g[:3]) for g in np.asarray(gains)]
    limit = FOLLOW_SHARE * min(peaks)
    t = np.arange(0.0, sc.run.duration + 1e-9, 0.05)
    asked = max(abs(float(speed_profile(float(ti))[1])) for ti in t)
    if asked > limit:
        who = sc.members[int(np.argmin(peaks))].id
        then = (f"the virtual car changes speed at most {limit:.3f} m/s^2, slower than the "
                "profile" if sc.leader.bound_by_members else "leader.bound_by_members = false: "
                f"{who} cannot hold its slot")
        text = (f"leader.speed asks up to {asked:.2f} m/s^2; member {who}'s speed law (its "
                f"speed_gains) gives at most {min(peaks):.3f} m/s^2: {then} (docs/model.md, "
                "'Mixed formations')")
        meta.setdefault("warnings", []).append(text)
        import sys
        print(f"warning: {text}", file=sys.stderr)
    return limit if sc.leader.bound_by_members else float("inf")


def build_fleet(sc: Scenario) -> FleetConfig:
    vehicles = member_vehicles(sc)
    mu = road_mu(sc)
    params = None
    if sc.vehicle.model == "dynamic":
        linear = sc.vehicle.tire_law == "linear"
        kinds = {v: make_tires(v, mu, sc.vehicle.tire, linear=linear) for v in set(vehicles)}
        # the dynamic model takes over only where the RK4 step is stable (docs/model.md);
        # one blend for the fleet: the highest such speed of its vehicles
        v_low = max(stable_blend_speed(v, tires, sc.run.physics_step, LOW_SPEED_DEFAULT.v_low)
                    for v, tires in kinds.items())
        blend = replace(LOW_SPEED_DEFAULT, v_low=v_low,
                        v_high=v_low + (LOW_SPEED_DEFAULT.v_high - LOW_SPEED_DEFAULT.v_low))
        params = stack([bicycle_params(v, mu, kinds[v], blend, resistances=sc.energy.resistances,
                                       rho_air=sc.energy.air_density) for v in vehicles])
    ctl = sc.controller
    return FleetConfig(
        ids=tuple(m.id for m in sc.members),
        model=sc.vehicle.model,
        params=params,
        k=np.array([m.k if m.k is not None else ctl.k for m in sc.members]),
        k_theta=np.array([m.k_theta if m.k_theta is not None else ctl.k_theta for m in sc.members]),
        speed_gains=_member_gains(sc, "speed_gains"),
        yaw_gains=_member_gains(sc, "yaw_gains"),
        physics_step=sc.run.physics_step,
        law=sumo_law(ctl.law).HEAD_LAW if ctl.law in SUMO_LAWS else ctl.law,  # SUMO's: its head's
        pred=column_predecessors(sc),
        bumpers=tuple((v.a + v.front_overhang, v.length - v.a - v.front_overhang)
                      for v in vehicles),
        law_params=(_law_params(ctl),) * len(sc.members),
        variant=sc.vehicle.variant,
        variant_params=_variant_params(sc.vehicle),
    )


LANE_TOLERANCE_M = 1.0
"""Slots whose lateral offsets differ by less than this are in one lane of a column [m]."""


def _law_params(ctl) -> dict:
    """{law: {parameter: value}} of the platoon laws (their defaults where the scenario has no
    controller.acc, ... table) and of the other laws the scenario gives a table."""
    return {**{name: ctl.params(name).model_dump() for name in PLATOON_LAWS},
            **{name: p for name, p in ctl.law_params.items() if name not in PLATOON_LAWS}}


def _variant_params(vehicle) -> dict | None:
    """{parameter: value} of the scenario's model variant (vehicle.variant, its
    [vehicle.<variant>] table over its SPEC's defaults), None without one."""
    if vehicle.variant is None:
        return None
    return variant_params(vehicle.variant, vehicle.variant_params.get(vehicle.variant))


def column_predecessors(sc: Scenario) -> tuple[int, ...]:
    """The member ahead of each member in its column (-1: none): the nearest slot ahead
    (larger along-position: offset d_x, or slot.along on a road) in the same lane (lateral
    offset within LANE_TOLERANCE_M; a road slot's lanes count as 3.5 m each)."""
    along, lat = [], []
    for m in sc.members:
        if m.slot is not None:
            along.append(m.slot.along)
            lat.append(m.slot.across if m.slot.across is not None else 3.5 * m.slot.lanes)
        elif m.offset is not None:
            along.append(m.offset[0])
            lat.append(m.offset[1])
        else:
            along.append(np.nan)
            lat.append(np.nan)
    pred = []
    for i in range(len(along)):
        ahead = [j for j in range(len(along)) if j != i and along[j] > along[i]
                 and abs(lat[j] - lat[i]) < LANE_TOLERANCE_M]
        pred.append(min(ahead, key=lambda j: along[j]) if ahead else -1)
    return tuple(pred)


def build_free_leader(sc: Scenario) -> tuple[FreeLeader, tuple[float, float, float]]:
    ld = sc.leader
    leader = FreeLeader(profile(ld.speed), profile(ld.yaw_rate_deg_s, np.pi / 180.0),
                        sc.run.physics_step)
    return leader, (ld.x, ld.y, float(np.deg2rad(ld.heading_deg)))


def offsets(sc: Scenario) -> np.ndarray:
    """(n, 2) offsets (d_x, d_y) [m] of the members in the virtual car frame."""
    return np.array([m.offset for m in sc.members], dtype=float)


def build_initial_state(sc: Scenario, cfg: FleetConfig, vc: LeaderState) -> FleetState:
    pos = np.array([m.position for m in sc.members], dtype=float)
    heading = np.array([np.deg2rad(m.heading_deg) if m.heading_deg is not None else vc.theta
                        for m in sc.members])
    speed = np.array([m.speed if m.speed is not None else vc.v for m in sc.members])
    yaw_rate = np.deg2rad([m.yaw_rate_deg_s for m in sc.members])
    steer = np.deg2rad([m.steer_deg for m in sc.members])
    return initial_state(cfg, pos, heading, speed, yaw_rate, steer, rigid_targets(vc, offsets(sc)))


def comm_channel(sc: Scenario, n_ctrl: int) -> CommChannel:
    """The [comm] radio of the formation ``sc`` sees (comm/link.py), drawn from the run's seed."""
    ids = [m.id for m in sc.members]
    ch = build_channel([link_params(sc.comm, i) for i in ids], sc.run.seed, sc.run.duration,
                       sc.run.control_step, sc.comm.beacon_hz, sc.comm.outages)
    return CommChannel(ch, ids, n_ctrl, sc.comm.timeout_s, vehicle_params(sc), sc.leader,
                       law_fallback=sc.controller.fallback_acc)


def with_comm(sc: Scenario, parts, baseline: bool = False):
    """``parts`` (sim/loop.py RunParts) with each formation's [comm] channel as the first of
    its transforms (none in a baseline twin: no formation)."""
    if baseline:
        return parts
    n_ctrl = int(round(sc.run.step / sc.run.control_step))
    views = dict(formation_views(sc))
    for f in parts.formations:
        view = views[f.id]
        if view.comm is not None:
            f.transforms.insert(0, comm_channel(view, n_ctrl))
    return parts
