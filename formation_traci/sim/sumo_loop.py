"""A formation run on a SUMO road among SUMO's traffic.

Per SUMO step (formation time t, SUMO time = warm-up + t):
1. read back where SUMO put the members and the vehicles near them, and what SUMO reported;
2. the governor sets the virtual car's acceleration for the step (time gaps of every member
   to the vehicle ahead of it) and caps the speed reference of members with a cut-in ahead;
3. record row t; 4. run the controllers and models over the step (control sub-steps);
5. place the members with moveToXY, step SUMO, tell SUMO their true speed and acceleration.
The virtual car drives along the reference lane (road/leader.py), slots follow the road
(road/targets.py) or the virtual car's frame (eq 2.4).
"""
from __future__ import annotations

import math
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from ..control.formation import rigid_targets, Targets
from ..models.params import VehicleParams
from ..record.columns import SSM_COLUMNS
from ..record.writer import ChunkedTable
from ..road.leader import road_leader_state
from ..road.targets import road_targets
from ..scenario.schema import Scenario
from . import fleet as fl
from .governor import governor_step
from .fast import FastFleet, SIGNAL_COLUMNS
from .recorder import Recorder
from .road_setup import (Road, build_road, check_no_overlap, check_slots, rectangles_overlap,
                         slot_offsets)
from .setup import build_fleet, gain_schedule, profile, road_mu, vehicle_params
from .sumo_adapter import MemberType, SumoAdapter
from .messages import SUMO_ARGS as SUMO_QUIET, sumo_outputs_meta
from .demand import measure_plan, traffic_meta
from .traffic import flow_vehicles_per_hour, write_routes

MEMBER_ROUTE = "formation_route"
MEMBER_VCLASS = {"passenger_car": "custom1", "small_truck": "custom2"}
"""Members' own SUMO vehicle classes: lane permissions can keep them (only) off the internal
lanes where the network's connections cross its lane geometry (road/lanes.py)."""
ADHESION_SHARE_COMFORT = 0.5
"""The virtual car's acceleration and comfortable deceleration are at most this share of mu g."""
ADHESION_SHARE_EMERGENCY = 0.8
"""Its emergency deceleration is at most this share of mu g (the members must be able to follow)."""
PLACEMENT_TOLERANCE = 0.1
"""SUMO's position of a member farther than this from ours is a placement_mismatch event [m]."""
MAX_REFUSED = 20
"""A member whose moveToXY is refused this many steps in a row is taken out of the run."""

INSERT_CLEAR_TIME = 1.0
"""Free space kept behind every member when it is inserted, as time at its speed [s]."""


@dataclass(frozen=True)
class RoadPlan:
    """Everything prepared and checked before SUMO starts."""

    road: Road
    veh: VehicleParams
    slots: np.ndarray  # (n, 2) road-frame (along, across) [m]; NaN rows for rigid members
    rigid: np.ndarray  # (n, 2) virtual-car-frame offsets [m]; NaN rows for road members
    is_road: np.ndarray  # (n,) bool
    pos0: np.ndarray  # (n, 2) initial CoG [m]
    heading0: np.ndarray  # (n,) [rad]
    speed0: np.ndarray  # (n,) [m/s]


def prepare(sc: Scenario, source: Path | None) -> RoadPlan:
    """Resolve and check the road and the formation; raises ScenarioError before anything runs."""
    road = build_road(sc, source)
    veh = vehicle_params(sc)
    slots = slot_offsets(sc, road)
    check_slots(sc, road, slots, veh, source)
    is_road = np.array([m.slot is not None for m in sc.members])
    rigid = np.array([m.offset if m.offset is not None else [np.nan, np.nan] for m in sc.members], float)
    v0, v0_dot = profile(sc.leader.speed)(0.0)
    tg = _targets(road, slots, rigid, is_road, sc.road.start, v0, 0.0)
    pos0 = tg.p.copy()
    heading0 = np.arctan2(tg.v[:, 1], tg.v[:, 0])
    speed0 = np.hypot(tg.v[:, 0], tg.v[:, 1])
    for i, m in enumerate(sc.members):
        if m.position is not None:
            pos0[i] = m.position
            heading0[i] = float(road.line.heading(road.line.to_frenet(np.asarray([m.position]))[0][0]))
        if m.heading_deg is not None:
            heading0[i] = math.radians(m.heading_deg)
        if m.speed is not None:
            speed0[i] = m.speed
    check_no_overlap(sc, pos0, heading0, veh, source)
    return RoadPlan(road, veh, slots, rigid, is_road, pos0, heading0, speed0)


def _targets(road: Road, slots, rigid, is_road, s, v, a) -> Targets:
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


def sumo_args(sc: Scenario, net: Path, routes: Path, sumo_dir: Path, t_end: float) -> list[str]:
    args = ["-n", str(net), "-r", str(routes), "--step-length", repr(sc.run.step),
            "--begin", "0", "--end", repr(t_end), "--seed", str(sc.run.seed),
            "--lateral-resolution", repr(sc.sumo.lateral_resolution),
            "--collision.action", "warn", "--collision.mingap-factor", "0",
            "--collision.check-junctions", "true",
            "--no-step-log", "true", "--log", str(sumo_dir / "sumo.log"),
            "--error-log", str(sumo_dir / "messages.log"), *SUMO_QUIET,
            "--duration-log.disable", "true"]
    if sc.sumo.ssm:
        args += ["--device.ssm.probability", "1", "--device.ssm.file", str(sumo_dir / "ssm.xml"),
                 "--device.ssm.measures", "TTC DRAC PET", "--device.ssm.thresholds", "3.0 3.0 2.0",
                 "--device.ssm.range", "50"]
    if sc.sumo.friction_device:
        args += ["--device.friction.probability", "1", "--device.friction.stdDev", "0"]
    if sc.sumo.fcd:
        args += ["--fcd-output", str(sumo_dir / "fcd.parquet")]
    return args + list(sc.sumo.options)


def member_type(sc: Scenario, veh: VehicleParams) -> MemberType:
    return MemberType(id=f"member_{sc.vehicle.preset}", length=veh.length, width=veh.width,
                      d_front=veh.cog_to_front_bumper, color=veh.color,
                      vclass=MEMBER_VCLASS[sc.vehicle.preset])


def _advance_vc(s, v, a, dt):
    """Virtual car along the line with constant acceleration a over dt; stops at v = 0."""
    if v + a * dt >= 0.0:
        return s + v * dt + 0.5 * a * dt * dt, v + a * dt
    t_stop = v / -a
    return s + v * t_stop + 0.5 * a * t_stop * t_stop, 0.0


def sumo_steps(sc: Scenario, rec: Recorder, out_dir: Path, source: Path | None, meta: dict,
               plan: RoadPlan | None = None, baseline: bool = False,
               step_hook=None) -> Iterator[tuple[int, float]]:
    """Run ``sc`` on its SUMO road; yields (step index, time [s]) after recording each step.

    ``baseline``: the twin run for comparisons: the same traffic and seed without the
    formation (no member enters SUMO; every vehicle is recorded; the virtual car's rows are
    kept as the reference of where the formation would have been).
    ``step_hook(k, t, adapter)``, if given, is called after every SUMO step (fault injection in
    tests, extensions)."""
    plan = plan or prepare(sc, source)
    road, veh, line = plan.road, plan.veh, plan.road.line
    run, ld = sc.run, sc.leader
    n_steps = int(round(run.duration / run.step))
    n_ctrl = int(round(run.step / run.control_step))
    dt_c = run.step / n_ctrl
    ids = [m.id for m in sc.members]
    n = len(ids)
    cfg = build_fleet(sc)
    speed_profile = profile(ld.speed)
    # the virtual car never asks for more than the road's adhesion allows the members
    mu_g = road_mu(sc) * 9.81
    accel_max = min(ld.accel_max, ADHESION_SHARE_COMFORT * mu_g)
    decel_max = min(ld.decel_max, ADHESION_SHARE_COMFORT * mu_g)
    decel_emergency = min(ld.decel_emergency, ADHESION_SHARE_EMERGENCY * mu_g)
    half_w = np.full(n, veh.width / 2)
    d_front = veh.cog_to_front_bumper
    along = np.where(plan.is_road, plan.slots[:, 0], plan.rigid[:, 0])  # slot ahead of the virtual car [m]
    along_max = float(np.max(along))

    sumo_dir = out_dir / "sumo"
    sumo_dir.mkdir(exist_ok=True)
    warm_steps = int(round(sc.traffic.warmup / run.step))
    t0 = warm_steps * run.step
    t_sumo_end = t0 + run.duration + 2 * run.step
    flows = []
    for f in sc.traffic.flows:
        edges, lanes = road.flow_routes[f.id]
        flows.append((f, edges, flow_vehicles_per_hour(f, lanes)))
    routes = write_routes(sumo_dir / "traffic.rou.xml", flows, t_sumo_end)
    flows = [(f, e, vph, f.end if f.end is not None else t_sumo_end) for f, e, vph in flows]
    measure = measure_plan(sc, road, sumo_dir)

    s_vc, v_vc = float(sc.road.start), speed_profile(0.0)[0]
    tg0 = _targets(road, plan.slots, plan.rigid, plan.is_road, s_vc, v_vc, 0.0)
    x0 = plan.pos0
    yaw0 = plan.speed0 * line.curvature(line.to_frenet(x0)[0])
    state = fl.initial_state(cfg, x0, plan.heading0, plan.speed0, yaw0, np.zeros(n), tg0)
    # compiled per-step path, checked against the numpy reference on a synthetic state here
    ff = FastFleet.from_config(cfg, line, plan.slots, plan.rigid, plan.is_road)
    sig_buf = np.full((n, len(SIGNAL_COLUMNS)), np.nan)
    m_s = None

    adapter = SumoAdapter(sc.sumo.backend, sc.sumo.gui)
    args = sumo_args(sc, road.net_file, routes, sumo_dir, t_sumo_end)
    if measure is not None:
        args += ["-a", str(measure["file"])]
    meta["sumo"] = {"args": args, "warmup": t0, "net": str(road.net_file), "route": road.route,
                    "reference_lane": sc.road.lane}
    meta["members"] = [{"id": m.id, "frame": "road" if plan.is_road[i] else "vehicle",
                        "offset": (plan.slots[i] if plan.is_road[i] else plan.rigid[i]).tolist(),
                        "lanes": None if m.slot is None else m.slot.lanes}
                       for i, m in enumerate(sc.members)]
    try:
        if sc.sumo.attach_port is not None:
            meta["sumo"]["args"] = f"attached to port {sc.sumo.attach_port}"
            meta["sumo"]["version"] = adapter.attach(sc.sumo.attach_port)
        else:
            meta["sumo"]["version"] = adapter.start(args)
        meta["versions"]["sumo"] = meta["sumo"]["version"]
        adapter.count_departures([f.id for f in sc.traffic.flows])
        mu = road_mu(sc)
        adapter.set_friction(mu)
        adapter.add_route(MEMBER_ROUTE, road.route)
        mtype = member_type(sc, veh)
        adapter.add_member_type(mtype)
        adapter.forbid_lanes(road.member_forbidden, MEMBER_VCLASS.values())
        for _ in range(warm_steps):
            adapter.simulation_step()

        active = np.ones(n, dtype=bool)
        inserted = False
        all_bg = sc.traffic.record_radius is None or baseline
        prev_lane: dict[str, tuple[str, int]] = {}
        member_lane_prev = np.full(n, -1)
        refused_run = np.zeros(n, dtype=int)
        mismatch = np.zeros(n, dtype=bool)
        ctx_owner = None
        slot_d_0 = np.where(plan.is_road, plan.slots[:, 1], plan.rigid[:, 1])
        emergency = False
        ev = None
        tm = meta["timing_s"] = {"sumo_step": 0.0, "sumo_read": 0.0, "sumo_place": 0.0,
                                 "governor": 0.0, "control_model": 0.0, "record": 0.0}
        clock = time.perf_counter
        for k in range(n_steps + 1):
            c0 = clock()
            t = k * run.step
            pos, vel, heading = ff.kinematics(state)
            v_m = np.hypot(vel[:, 0], vel[:, 1])
            m_s, m_d = ff.to_frenet(pos, m_s)
            extra = {"s": m_s, "d": m_d}
            nb = None
            if inserted and baseline:
                _log_sumo_events(rec, t, ev, set(ids))
                nb = adapter.neighbours(True)
            elif inserted:
                act = [ids[i] for i in np.flatnonzero(active)]
                xs, ys, _, lanes, lane_idx, lat, present = adapter.read_members(act)
                idx_act = np.flatnonzero(active)
                for j, i in enumerate(idx_act):
                    if not present[j]:
                        rec.add_event(t, "member_removed", ids[i], "", "SUMO no longer has the member")
                        active[i] = False
                gap_sumo = np.full(n, np.nan)
                lane_index = np.full(n, np.nan)
                gap_sumo[idx_act] = _sumo_gap(road, pos[idx_act], heading[idx_act], d_front, xs, ys, lanes,
                                              adapter.lane_pos, lat)
                lane_index[idx_act] = np.where(present, lane_idx, np.nan)
                extra.update(sumo_gap=gap_sumo, lane_index=lane_index)
                off = gap_sumo > PLACEMENT_TOLERANCE
                for i in np.flatnonzero(off & ~mismatch):
                    rec.add_event(t, "placement_mismatch", ids[i], "",
                                  f"SUMO has the member {gap_sumo[i]:.2f} m from where the model put it")
                mismatch = off
                for j, i in enumerate(idx_act):
                    if present[j] and member_lane_prev[i] >= 0 and lane_idx[j] != member_lane_prev[i] \
                            and lanes[j].rsplit("_", 1)[0] == prev_lane.get(ids[i], ("", -1))[0]:
                        rec.add_event(t, "lane_change", ids[i], "", f"{member_lane_prev[i]} -> {lane_idx[j]}")
                    if present[j]:
                        member_lane_prev[i] = lane_idx[j]
                        prev_lane[ids[i]] = (lanes[j].rsplit("_", 1)[0], int(lane_idx[j]))
                _log_sumo_events(rec, t, ev, set(ids))
                nb = adapter.neighbours(all_bg)
            c1 = clock()
            tm["sumo_read"] += c1 - c0
            # governor: the virtual car keeps every slot a time gap behind the vehicle ahead of
            # it; each member keeps its own gap to whatever is between it and its slot
            slot_s = s_vc + along
            slot_d = np.where(plan.is_road, plan.slots[:, 1], m_d)
            if nb is not None and len(nb.ids):
                nb_s, nb_d = ff.to_frenet(np.column_stack([nb.x, nb.y]))
                nb_rear, nb_hw, nb_v = nb_s - nb.length / 2, nb.width / 2, nb.v
            else:
                nb_s = nb_d = nb_rear = nb_hw = nb_v = np.empty(0)
            v_set, v_set_dot = speed_profile(t)
            a_vc, gap, lead_idx, v_cap, a_cap = governor_step(
                m_s + d_front, m_d, slot_s + d_front, slot_d, half_w, v_m, active, v_vc, v_set, v_set_dot,
                nb_rear, nb_d, nb_hw, nb_v, ld.time_gap, ld.min_gap, accel_max, decel_emergency)
            if a_vc < -decel_max - 1e-9 and not emergency:
                rec.add_event(t, "emergency_brake", "vc", "", f"virtual car decelerates at {-a_vc:.2f} m/s^2")
            emergency = a_vc < -decel_max - 1e-9
            c2 = clock()
            tm["governor"] += c2 - c1
            if nb is not None:
                _lane_changes(rec, t, nb, prev_lane, lead_idx, gap, v_m, ids, active, ld)
                rec.add_background(t, nb, nb_s, nb_d)

            vc = ff.leader_state(s_vc, v_vc, a_vc)
            if not baseline:
                rec.add_signal_rows(t, ff.signals(state, s_vc, v_vc, a_vc, v_cap, a_cap, out=sig_buf),
                                    extra, mask=active)
            rec.add_vc(t, vc, s=s_vc)
            c3 = clock()
            tm["record"] += c3 - c2
            yield k, t
            if k == n_steps:
                return
            if s_vc + along_max + d_front + sc.road.end_margin > line.length:
                rec.add_event(t, "end_of_road", "vc", "", f"formation front within {sc.road.end_margin} m of the route end")
                meta["stopped_early"] = f"end of the route reached at t = {t:.2f} s"
                return
            if not active.any():
                meta["stopped_early"] = f"no member left in SUMO at t = {t:.2f} s"
                return

            c3 = clock()
            v_before = state.x[:, 3].copy() if cfg.model == "dynamic" else state.speed_in.copy()
            state, s_vc, v_vc = ff.step(state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl)
            if not np.all(np.isfinite(state.x)):
                from .runner import check_finite
                check_finite(state, ids, t + run.step)
            pos, vel, heading = ff.kinematics(state)
            v_after = state.x[:, 3] if cfg.model == "dynamic" else state.speed_in
            a_mean = (v_after - v_before) / run.step
            c4 = clock()
            tm["control_model"] += c4 - c3
            act_idx = np.flatnonzero(active)
            act = [ids[i] for i in act_idx]
            if baseline:
                pass  # the formation stays out of SUMO
            elif not inserted:
                _clear_insertion_zone(adapter, rec, t + run.step, pos, heading, v_after, veh,
                                      ld.min_gap + ld.time_gap * v_after)
                for i in act_idx:
                    adapter.insert_member(ids[i], MEMBER_ROUTE, mtype, pos[i, 0], pos[i, 1], heading[i], v_after[i])
            else:
                refused = dict(adapter.place(act, pos[act_idx, 0], pos[act_idx, 1], heading[act_idx]))
                for i in act_idx:
                    if ids[i] in refused:
                        refused_run[i] += 1
                        rec.add_event(t + run.step, "move_refused", ids[i], "", refused[ids[i]])
                        if refused_run[i] >= MAX_REFUSED:
                            active[i] = False
                            adapter.remove_vehicle(ids[i])
                            rec.add_event(t + run.step, "member_removed", ids[i], "",
                                          f"dropped after {MAX_REFUSED} refused moves in a row")
                    else:
                        refused_run[i] = 0
                act_idx = np.flatnonzero(active)
                act = [ids[i] for i in act_idx]
            c5 = clock()
            ev = adapter.step()
            c6 = clock()
            tm["sumo_place"] += c5 - c4
            tm["sumo_step"] += c6 - c5
            if step_hook is not None:
                step_hook(k, t + run.step, adapter)
            if baseline:
                adapter.subscribe_departed()
                inserted = True  # reads neighbours (every vehicle) from now on
                continue
            adapter.set_true_speeds(act, v_after[act_idx], a_mean[act_idx])
            if not all_bg and active.any() and (not inserted or ctx_owner is None or not active[ctx_owner]):
                ctx_owner = _subscribe_context(adapter, ids, active, along, slot_d_0, sc.traffic.record_radius)
            inserted = True
            if all_bg:
                adapter.subscribe_departed()
            tm["sumo_place"] += clock() - c6
    finally:
        t_sumo = adapter.time if adapter._started else t0
        adapter.close()
        _convert_ssm(sumo_dir / "ssm.xml", out_dir / "ssm.parquet", t0, set(ids))
        traffic_meta(meta, rec, flows, adapter.departed, t_sumo, t0, measure)
        sumo_outputs_meta(meta, sc, rec, sumo_dir, t0, {i: d_front for i in ids})


def _sumo_gap(road, pos, heading, d_front, xs, ys, lanes, lane_pos, lat):
    """How far SUMO has each member from our pose [m]: the larger of the position gap and the
    distance between our front bumper and the point SUMO's lane, lane position and lateral
    lane position give (SUMO's lane shapes, road/lanes.py). (In the step of a move SUMO
    echoes the commanded x, y even where it put the vehicle on another lane.)"""
    gap = np.hypot(xs - pos[:, 0], ys - pos[:, 1])
    fx = pos[:, 0] + d_front * np.cos(heading)
    fy = pos[:, 1] + d_front * np.sin(heading)
    for j, lane in enumerate(lanes):
        if lane and np.isfinite(lat[j]) and np.isfinite(lane_pos[j]):
            sx, sy = road.shapes.xy(lane, lane_pos[j], lat[j])
            gap[j] = max(gap[j], math.hypot(sx - fx[j], sy - fy[j]))
    return gap


def _subscribe_context(adapter, ids, active, along, across, radius):
    """One context subscription for the whole formation: on the active member nearest the
    middle of the formation, with the radius grown by the formation's extent around it.
    Returns that member's index."""
    idx = np.flatnonzero(active)
    centre = np.array([along[idx].mean(), across[idx].mean()])
    dist = np.hypot(along[idx] - centre[0], across[idx] - centre[1])
    owner = int(idx[np.argmin(dist)])
    extent = float(np.max(np.hypot(along[idx] - along[owner], across[idx] - across[owner])))
    adapter.subscribe_neighbours(ids[owner], radius + extent)
    return owner


def _log_sumo_events(rec, t, ev, members):
    if ev is None:
        return
    for collider, victim, lane in ev.collisions:
        rec.add_event(t, "collision", collider, victim, f"lane {lane}")
    for vid in ev.teleports:
        rec.add_event(t, "teleport", vid, "", "member" if vid in members else "")


def _lane_changes(rec, t, nb, prev_lane, lead_idx, gap, v_m, ids, active, ld):
    """Lane-change events of nearby vehicles; a cut-in when one becomes the vehicle right
    ahead of a member inside its time gap."""
    changed = set()
    for j, vid in enumerate(nb.ids):
        edge = nb.lane_ids[j].rsplit("_", 1)[0]
        li = int(nb.lane_index[j])
        old = prev_lane.get(vid)
        if old is not None and old[0] == edge and old[1] != li and not edge.startswith(":"):
            rec.add_event(t, "lane_change", vid, "", f"{old[1]} -> {li}")
            changed.add(j)
        prev_lane[vid] = (edge, li)
    for i in np.flatnonzero(active):
        j = lead_idx[i]
        if j >= 0 and j in changed and gap[i] < ld.min_gap + ld.time_gap * v_m[i]:
            rec.add_event(t, "cut_in", nb.ids[j], ids[i], f"gap {gap[i]:.1f} m ahead of the member")


def _clear_insertion_zone(adapter, rec, t, pos, heading, v, veh, front):
    """Remove SUMO vehicles that stand where a member is inserted, or inside its time gap
    ahead (``front`` [m]) or within INSERT_CLEAR_TIME of its speed behind it."""
    ids, x, y, psi, length, width = adapter.vehicle_bodies()
    for j, vid in enumerate(ids):
        for i in range(len(pos)):
            back = max(2.0, v[i] * INSERT_CLEAR_TIME)
            zone_len = veh.length + front[i] + back
            shift = (front[i] - back) / 2
            zc = pos[i] + shift * np.array([math.cos(heading[i]), math.sin(heading[i])])
            if rectangles_overlap(zc, heading[i], np.array([x[j], y[j]]), psi[j], zone_len, veh.width + 0.6,
                                  length[j], width[j]):
                adapter.remove_vehicle(vid)
                rec.add_event(t, "cleared_at_insertion", vid, "", "removed: it stood where a member is inserted")
                break


def _convert_ssm(xml_path: Path, out: Path, t0: float, members: set[str]) -> None:
    """SUMO's SSM XML (one <conflict> per encounter) -> ssm.parquet; a truncated file keeps
    the conflicts read before the damage."""
    if not xml_path.exists():
        return
    table = ChunkedTable(out, SSM_COLUMNS, chunk_rows=100_000, labels=[""])
    f = lambda v: float(v) if v not in (None, "", "NA") else np.nan
    try:
        for _, el in ET.iterparse(xml_path):
            if el.tag != "conflict":
                continue
            ego, foe = el.get("ego", ""), el.get("foe", "")
            ttc, drac, pet = el.find("minTTC"), el.find("maxDRAC"), el.find("PET")
            table.append({
                "begin": f(el.get("begin")) - t0, "end": f(el.get("end")) - t0,
                "ego": table.code(ego), "foe": table.code(foe),
                "member_involved": ego in members or foe in members,
                "min_ttc": f(ttc.get("value")) if ttc is not None else np.nan,
                "min_ttc_time": (f(ttc.get("time")) - t0) if ttc is not None else np.nan,
                "max_drac": f(drac.get("value")) if drac is not None else np.nan,
                "max_drac_time": (f(drac.get("time")) - t0) if drac is not None else np.nan,
                "pet": f(pet.get("value")) if pet is not None else np.nan}, 1)
            el.clear()
    except ET.ParseError:
        pass  # keep what was parsed
    table.close()
