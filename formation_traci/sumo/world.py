"""SUMO as the World of a road run (over the one libsumo adapter, sumo/adapter/__init__.py).

sense: read back where SUMO put the members (removed, placement mismatch, lane changes)
and the vehicles near them; observe: traffic events and background rows; actuate: insert
the members spawned since the last step (every member of the run before its first step),
place the others with moveToXY (their pose, speeds and accelerations as SUMO takes them:
sumo/types.py sumo_placement); retire: members out of SUMO at once; step: SUMO's step, then tell
SUMO the members' true speed and acceleration. A baseline twin (``baseline`` "same" or
"absent") runs the same traffic without the formation: no member enters SUMO, every vehicle is
recorded; the "same" twin has, in each member's place, a vehicle of its type that SUMO drives.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..record.ssm import SsmConverter
from ..road.line_pack import FastLine, packed
from ..scenario.schema import Scenario
from .events import (PLACEMENT_TOLERANCE, EmergencyWatch, LaneTracker, MemberWatch, RefusalWatch,
                     TrafficWatch, log_sumo_events)
from .zone import clear_insertion_zone, middle_member, subscribe_context
from .sections import (drain as drain_stretch, plan_sections, sumo_options as section_options,
                       write_tables as write_sections)
from ..sim.incidents import clearance_lookup
from .demand import measure_plan, report_formation_shortfall, traffic_meta
from .join import inside_formation
from .messages import sumo_outputs_meta
from .adapter import SumoAdapter
from ..sim.formation import virtual_car_id
from .adapter.neighbours import NOBODY
from .flow_inserts import RoomCheck, counted_entry, flow_counts
from .handover import MemberHandover
from .member_rows import MemberRows
from .peers import Peers
from .sense import NeighbourGuess, NeighbourReads, PackedLanes, SumoRows, sense_step
from .types import Neighbours, sumo_placement
from .plan import MEMBER_ROUTE, MEMBER_VCLASS, RoadPlan, member_types, sumo_args
from .traffic import flow_vehicles_per_hour, populate_places, write_routes
from .warm_state import WarmSetup, merge_outputs, start_warm
from ..sim.world import Sensed, sensed_of

_NO_ROWS = (np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0, dtype=np.int64))
"""sense_step's SUMO rows of the members when they are not in SUMO (not inserted yet, a baseline)."""
_NO_NB = (np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0))
"""sense_step's neighbour rows when there is no neighbour."""


class SumoWorld(MemberHandover, MemberRows):
    """The members among SUMO's traffic on the plan's road (see the module docstring)."""

    def __init__(self, sc: Scenario, plan: RoadPlan, fleet, rec, out_dir: Path, meta: dict,
                 baseline: bool = False, step_hook=None):
        self.sc, self.plan, self.fleet, self.rec, self.meta = sc, plan, fleet, rec, meta
        self.baseline, self.step_hook = baseline, step_hook
        self.twin_same = baseline == "same"  # the same-demand twin (docs/metrics.md, "The twins")
        self.records_members = not baseline
        self.ids = list(plan.ids) if plan.ids else [m.id for m in sc.members]
        self._id_set = set(self.ids)
        n = len(self.ids)
        self.groups = [rows for _, _, rows in plan.formations] or [slice(0, n)]  # formations' rows
        self.line = FastLine(float(plan.road.line.length), packed(plan.road.line))  # packed once per line
        self.out_dir, self.sumo_dir = out_dir, out_dir / "sumo"
        self.active = np.ones(n, dtype=bool)  # members in the run
        self.in_sumo = np.zeros(n, dtype=bool)  # members SUMO has (inserted, not removed)
        self.moved = np.ones(n, dtype=bool)  # members placed by moveToXY (False: SUMO drives, sumo/driven.py)
        self.adds: list[str] = []  # further SUMO additional files (sumo/driven.py: its vTypes)
        self._every = np.arange(n)
        for mv in sc.maneuvers:  # a joining member enters when it takes a vehicle over
            if mv.kind == "join":
                self.active[self.ids.index(mv.member)] = False
        self.waiting = np.zeros(n, dtype=bool)  # members of formations that depart later
        for setup, _, rows in plan.formations:
            self.waiting[rows] = setup.depart > 0 or bool(setup.flow)
        self.flows_inserted = {}  # formation flow id -> formations that entered
        self.active &= ~self.waiting
        self.pending = np.flatnonzero(self.active)  # spawned, inserted at the next actuate
        self.sumo_ids = list(self.ids)  # SUMO's vehicle of each member (join: the one taken over)
        self.adopting = []  # take-overs to write into the fleet state (sumo/join.py)
        self.route_id = MEMBER_ROUTE
        self.slot_index = np.arange(n, dtype=float)  # the 'slot' column; maneuvers change it
        self.inserted = False
        self.sections = None  # the measurement sections (sumo/sections.py), set at start
        self.should_stop = None  # polled by the drain (the run's stop flag: Ctrl-C ends it)
        self.all_bg = sc.traffic.record_radius is None or baseline
        self.ctx_owner = [None] * len(self.groups)  # each formation's context subscription
        self.m_s = np.full(n, np.nan)  # members' arc length at the last sense [m] (NaN: none yet)
        self.packed_lanes = PackedLanes(plan.road.shapes)
        self.nb_guess = NeighbourGuess()  # the neighbours' arc lengths at the last sense
        self.ev = None
        self.released: set[str] = set()  # SUMO ids of members handed over by a leave
        self.true_v = {} if sc.sumo.fcd and sc.sumo.fcd_frame == "formation" else None  # k -> v [m/s]
        self._kin = None  # (state, pos, vel, heading) of the state last placed
        self.along = np.where(plan.is_road, plan.slots[:, 0], plan.rigid[:, 0])
        self.slot_d_0 = np.where(plan.is_road, plan.slots[:, 1], plan.rigid[:, 1])
        lanes = LaneTracker()
        self.members = MemberWatch(rec, self.ids, lanes, self.sumo_dir / "messages.log")
        self.traffic = TrafficWatch(rec, self.ids, lanes, sc.leader.time_gap, sc.leader.min_gap)
        self.emergency = EmergencyWatch(rec, self.ids, [virtual_car_id(setup.id, len(self.groups))
                                                        for setup, _, _ in plan.formations] or None)
        self.followed = None  # the member sumo-gui's view follows
        self.refusals = RefusalWatch(rec, self.ids, self.sumo_ids)
        self.lanes_read = (self._every[:0], [])  # (member rows, their SUMO lane ids) of the last read
        if not baseline:  # where an incident happened (sim/incident_log.py)
            rec.incident_log.locate = self.locate
        self.mtypes = member_types(sc, plan)
        self.d_front = np.array([mt.d_front for mt in self.mtypes])  # CoG to front bumper [m]
        self.placement = np.empty((6, n))  # actuate's sumo/types.py sumo_placement rows
        # ramp traffic at the route's joins (sumo/merge_watch.py; set by run/road_parts.py), each formation's cap [m/s^2]
        self.merges, self.merge_caps = None, np.full(len(self.groups), np.inf)
        self._room = None  # sumo/flow_inserts.py RoomCheck, made at the first due formation of a flow
        self.peers = Peers(self.ids, self.sumo_ids, self.mtypes, self.groups) if len(self.groups) > 1 else None
        self.adapter = SumoAdapter(sc.sumo.backend, sc.sumo.gui)
        if sc.sumo.ssm != "off":  # converted as the run goes, cut with the other tables (record/ssm.py)
            t0 = int(round(sc.traffic.warmup / sc.run.step)) * sc.run.step
            rec.ssm = SsmConverter(self.sumo_dir / "ssm.xml", out_dir / "ssm.parquet", t0, set(self.ids),
                                   plan.road.line)

    # ------------------------------------------------------------------ start / close
    def start(self) -> None:
        sc, run, road = self.sc, self.sc.run, self.plan.road
        self.sumo_dir.mkdir(exist_ok=True)
        warm_steps = int(round(sc.traffic.warmup / run.step))
        self.t0 = warm_steps * run.step
        t_sumo_end = self.t0 + run.duration + 2 * run.step
        flows = []
        for f in sc.traffic.flows:
            edges, lanes = road.flow_routes[f.id]
            vph = flow_vehicles_per_hour(f, lanes)
            if self.plan.flow_keep and f.id in self.plan.flow_keep:  # a formation flow's share
                vph *= self.plan.flow_keep[f.id]
            flows.append((f, edges, vph))
        populated = {f.id: populate_places(vph, road.speed_limit, [road.edge_length[e] for e in edges],
                                           run.seed)
                     for f, edges, vph in flows if f.populate}
        self.populated = {fid: len(p) for fid, p in populated.items()}
        routes = write_routes(self.sumo_dir / "traffic.rou.xml", flows, t_sumo_end, populated)
        self.flows = [(f, e, vph, f.end if f.end is not None else t_sumo_end) for f, e, vph in flows]
        self.measure = measure_plan(sc, road, self.sumo_dir)
        self.sections = plan_sections(sc, road, self.sumo_dir)
        drain_s = sc.traffic.sections.drain_max if self.sections is not None else 0.0
        args = sumo_args(sc, road.net_file, routes, self.sumo_dir, t_sumo_end + drain_s, self.ids)
        adds = ([str(self.measure["file"])] if self.measure is not None else []) + self.adds
        if self.sections is not None:
            adds.append(str(self.sections["file"]))
        if adds:
            args += ["-a", ",".join(adds)]
        args += section_options(self.sections)
        meta, plan = self.meta, self.plan
        meta["sumo"] = {"args": args, "warmup": self.t0, "net": str(road.net_file),
                        "route": road.route, "reference_lane": sc.road.lane,
                        "speed_limit_mps": road.speed_limit}
        meta["members"] = [dict(m, **{"frame": "road" if plan.is_road[i] else "vehicle",
                                      "offset": (plan.slots[i] if plan.is_road[i]
                                                 else plan.rigid[i]).tolist()})
                           for i, m in enumerate(meta["members"])]
        ad = self.adapter
        setup = WarmSetup(tuple(f.id for f in sc.traffic.flows), meta["mu"], MEMBER_ROUTE, tuple(road.route),
                          tuple({mt.id: mt for mt in self.mtypes}.values()), tuple(road.member_forbidden),
                          tuple(MEMBER_VCLASS.values()))
        if sc.sumo.attach_port is not None:
            meta["sumo"]["args"] = f"attached to port {sc.sumo.attach_port}"
            meta["sumo"]["version"] = ad.attach(sc.sumo.attach_port)
            setup.apply(ad)
            for _ in range(warm_steps):
                ad.simulation_step()
        else:  # the warm-up simulated here, or started from its shared state (sumo/warm_state.py)
            meta["sumo"]["version"] = start_warm(ad, args, setup, warm_steps, self.sumo_dir,
                                                 meta.get("warm_state"))
        meta["versions"]["sumo"] = meta["sumo"]["version"]

    def drain(self) -> None:
        """After the formation's last step (a run that ended normally): the sections' drain
        (sumo/sections.py): the members leave SUMO, SUMO runs on until the stretch is empty.
        What the run reports of its traffic stays the formation's part (the tables, the
        demand, the detectors, SUMO's messages and conflicts up to now)."""
        if self.sections is None or not self.adapter.started:
            return
        ad = self.adapter
        self._end = (ad.time, dict(ad.departed))
        t_end = ad.time - self.t0
        if self.rec.ssm is not None:
            self.rec.ssm.t_max = t_end
        members = [] if self.baseline else [v for v, a in zip(self.sumo_ids, self.active) if a]
        self.meta["sections"] = {"t_end": t_end, **drain_stretch(
            ad, self.sections, members, self.sc.traffic.sections.drain_max, self.sc.run.step,
            self.should_stop)}

    def close(self) -> None:
        t0 = getattr(self, "t0", 0.0)
        t_sumo = self.adapter.time if self.adapter.started else t0
        t_sumo, departed = getattr(self, "_end", (t_sumo, self.adapter.departed))
        try:
            self.adapter.close()  # SUMO completes its outputs; the recorder converts ssm.xml
            merge_outputs(self.sumo_dir, self.meta.get("warm_state"))  # a shared warm-up's part
        finally:
            if self.merges is not None:  # what the ramp vehicles did, per formation
                self.meta["merges"] = {"mode": self.merges.mode, "by_formation": self.merges.summary()}
            if self.plan.flow_share_of is not None:
                self.meta["formation_flows"] = flow_counts(self.plan, self.flows_inserted, t_sumo - t0,
                                                           self.adapter.departures, t0)
                self.meta.setdefault("warnings", []).extend(report_formation_shortfall(
                    self.meta["formation_flows"], self.rec.add_event, max(t_sumo - t0, 0.0)))
            if hasattr(self, "flows"):
                from .fcd import true_speeds  # pandas: imported only to end a run
                traffic_meta(self.meta, self.rec, self.flows, departed, t_sumo, t0, self.measure,
                             self.populated)
                sumo_outputs_meta(self.meta, self.sc, self.rec, self.sumo_dir, t0,
                                  {i: mt.d_front for i, mt in zip(self.ids, self.mtypes)},
                                  t_sumo - t0, true_speeds(self.true_v, self.ids), self.sumo_ids)
                self.meta.setdefault("sections", {}).update(write_sections(
                    self.out_dir, self.sections, self.adapter.departures, t0, set(self.ids)))

    # ------------------------------------------------------------------------- sense
    def sense(self, k: int, t: float, state) -> Sensed:
        pos, vel, heading = self._kinematics(state)
        self._kin = None  # adopt may write into this state after sense
        member_rows = self.inserted and not self.baseline  # a baseline twin has no member in SUMO
        rows = self._member_rows(t) if member_rows else _NO_ROWS
        nb_rows = self.adapter.neighbour_rows(self.all_bg) if self.inserted else None  # all: baseline
        nb_in = _NO_NB if nb_rows is None else (*nb_rows[2:4], *nb_rows[6:8], self.nb_guess(nb_rows[0]))
        lanes, n = self.packed_lanes, len(self.ids)
        s, d, v_m, gap, n_off, *nb_out = sense_step(
            self.line.G, pos, vel, self.m_s, heading, self.d_front, SumoRows(*rows[:5]),
            lanes.table, lanes.points, PLACEMENT_TOLERANCE, NeighbourReads(*nb_in))
        m_s, m_d = s[:n], d[:n]
        self.m_s = m_s
        sensed = Sensed(self.active, {"s": m_s, "d": m_d, "slot": self.slot_index}, v_m, m_s, m_d)
        if not self.inserted:
            return sensed
        if member_rows:
            sensed.extra.update(sumo_gap=gap, lane_index=rows[5])
            self.members.placement(t, gap, n_off)
            self.members.lane_changes(t, *rows[6:])
            if self.peers is not None:  # every member as the other formations' traffic
                self.peers.lanes(rows[6], rows[8], rows[5])
                self.peers.update(pos, heading, v_m, getattr(self, "a_mean", np.zeros(n)), m_s, m_d)
            if self.merges is not None:  # ramp traffic at the route's joins
                self.merge_caps = self.merges.limits(t, m_s, m_d, v_m, self.active & self.in_sumo)
                sensed.a_limit, sensed.a_limits = float(self.merge_caps[0]), self.merge_caps
        if nb_rows is None:
            sensed.nb = NOBODY
        else:
            ids, types, _, _, v, a, length, width, lane_ids, lane_index = nb_rows
            x, y, psi, sensed.nb_rear, sensed.nb_half_w = nb_out
            sensed.nb = Neighbours(ids, types, x, y, psi, v, a, length, width, lane_ids, lane_index)
            sensed.nb_s, sensed.nb_d, sensed.nb_v = s[n:], d[n:], v
            self.nb_guess.keep(ids, sensed.nb_s)
            if self.released:  # released members inside the formation (sumo/join.py)
                sensed.nb_in_formation = inside_formation(self.released, sensed, m_s + self.d_front,
                                                          self.plan.vehicles, self.active)
        ev = self.ev
        if ev is not None and (ev.collisions or ev.teleports):
            log_sumo_events(self.rec, t, ev, self._id_set, self.joined_names(),
                            clearance_lookup(self.rec.incidents, self.ids, self.active,
                                             pos, heading, sensed.nb))
        return sensed

    def observe(self, t: float, sensed: Sensed, ref) -> None:
        info = ref.info
        self.emergency(t, info)
        if sensed.nb is not None:
            self.traffic(t, sensed.nb, info["lead_idx"], info["gap"], sensed.v_m, self.active)
            self.rec.add_background(t, sensed.nb, sensed.nb_s, sensed.nb_d)

    def spawn(self, t: float, rows) -> None:
        """Members ``rows`` join the run; SUMO gets them at the next :meth:`actuate`, where
        their state puts them (vehicles standing there are cleared first)."""
        rows = np.atleast_1d(rows)
        self.active[rows] = True
        self.waiting[rows] = False
        self.pending = np.union1d(self.pending, rows).astype(np.int64)
        if self.plan.flow_share_of is not None:
            counted_entry(self.plan, self.flows_inserted, rows)

    def has_room(self, t: float, rows: slice, state) -> bool:
        """Room on the road for the members ``rows`` where their state puts them (a formation
        flow's formation enters only then: sumo/flow_inserts.py)."""
        if self._room is None:
            self._room = RoomCheck(self)
        return self._room(t, rows, state)

    def retire(self, t: float, rows, why: str) -> None:
        """Members ``rows`` leave the run and SUMO now (an event ``member_retired``)."""
        for i in np.atleast_1d(rows):
            if not self.active[i]:
                continue
            if self.in_sumo[i] and not self.baseline:
                self.adapter.remove_vehicle(self.sumo_ids[i])
            self.active[i] = self.in_sumo[i] = False
            self.rec.add_event(t, "member_retired", self.ids[i], "", why)
        self.pending = np.setdiff1d(self.pending, rows).astype(np.int64)

    def sensed_for(self, sensed: Sensed, rows: slice) -> Sensed:
        """What the formation of fleet rows ``rows`` senses: its members, and as its
        neighbours SUMO's vehicles and the other formations' members (sumo/peers.py); its
        cap for ramp traffic (sumo/merge_watch.py)."""
        if self.peers is None:
            part = sensed_of(sensed, rows)
        else:
            part = self.peers.sensed_for(sensed, rows, self.active & self.in_sumo)
        if self.merges is not None:  # each formation's own cap (sense gives the first one's)
            part.a_limit = float(self.merge_caps[self.merges.formation_at[rows.start]])
        return part

    def joined_neighbours(self, sensed: Sensed):
        """SUMO's vehicles and every member in SUMO as one neighbour table for a formation
        group (sim/formation_group.py, sumo/peers.py Peers.table)."""
        return self.peers.table(sensed, self.active & self.in_sumo)

    def stop_reason(self, t: float):
        if not self.active.any() and not self.waiting.any():
            return None, "", f"no member left in SUMO at t = {t:.2f} s"
        return None

    def subscribe_contexts(self) -> None:
        """One context subscription per formation with members in SUMO, on a member near its
        middle (sumo/zone.py), renewed when that member left."""
        here = self.active & self.in_sumo if len(self.groups) > 1 else self.active
        for g, rows in enumerate(self.groups):
            owner = self.ctx_owner[g]
            if owner is not None and self.active[owner] and self.inserted:
                continue
            mask = np.zeros_like(here)
            mask[rows] = here[rows]
            if mask.any():
                self.ctx_owner[g] = subscribe_context(self.adapter, self.sumo_ids, mask, self.along,
                                                      self.slot_d_0, self.sc.traffic.record_radius)

    # ------------------------------------------------------------------ actuate / step
    def actuate(self, t_next: float, state, v_before) -> None:
        pos, vel, heading = self._kinematics(state)
        place = self.placement  # SUMO's pose, speeds and mean accelerations of the new state
        sumo_placement(pos, heading, np.ascontiguousarray(v_before, dtype=np.float64), self.fleet.speed(state),
                       self.d_front, float(self.sc.run.step), place)
        v_after, self.a_mean, self.v_told = place[3].copy(), place[4].copy(), place[5].copy()
        self.v_after = v_after
        if self.true_v is not None:  # the members' true speeds for the FCD (sumo/fcd.py)
            self.true_v[int(round(t_next / self.sc.run.step))] = np.where(self.active, v_after, np.nan)
        ids, ad = self.ids, self.adapter
        act_idx = np.flatnonzero(self.active & self.in_sumo & self.moved)
        if len(self.pending):  # a twin clears the same vehicles at the same step (same state)
            self.insert_members(t_next, self.pending, pos, heading, v_after)
        if self.baseline or not len(act_idx):
            return  # a twin: the formation stays out of SUMO
        if len(act_idx) == len(ids):  # every member in the run: no copies
            refused = dict(ad.place(self.sumo_ids, place[0], place[1], place[2], place[5], pos))
        else:
            at = place[:, act_idx]
            refused = dict(ad.place([self.sumo_ids[i] for i in act_idx], at[0], at[1], at[2], at[5],
                                    pos[act_idx]))
        self.refusals(t_next, act_idx, refused, self.active, ad)

    def insert_members(self, t_next, rows, pos, heading, v_after) -> None:
        """SUMO gets the spawned members ``rows`` at their poses, vehicles standing there (or
        in their time gap ahead) cleared first; a twin clears the same vehicles and inserts
        no member (the same-demand twin: a SUMO-driven vehicle of each member's type there)."""
        ld, ad = self.sc.leader, self.adapter
        clear_insertion_zone(ad, self.rec, t_next, pos[rows], heading[rows], v_after[rows],
                             [self.plan.vehicles[i] for i in rows],
                             ld.min_gap + ld.time_gap * v_after[rows])
        self.pending = self.pending[:0]
        if self.baseline:
            if self.twin_same:  # the members' vehicles, driven by SUMO from here on
                for i in rows:
                    ad.add_twin_vehicle(self.ids[i], MEMBER_ROUTE, self.mtypes[i], pos[i, 0], pos[i, 1],
                                        heading[i], v_after[i])
            return
        for i in rows:
            ad.insert_member(self.ids[i], MEMBER_ROUTE, self.mtypes[i], pos[i, 0], pos[i, 1],
                             heading[i], v_after[i])
        self.in_sumo[rows] = True

    def step(self, k: int, t_next: float) -> None:
        ad = self.adapter
        self.ev = ad.step()
        if self.step_hook is not None:
            self.step_hook(k, t_next, ad)
        if self.baseline:
            ad.subscribe_departed()
            self.inserted = True  # reads neighbours (every vehicle) from now on
            return
        here_now = self.active & self.in_sumo & self.moved
        if here_now.all():
            ad.set_true_speeds(self.sumo_ids, self.v_told, self.a_mean)
        else:
            act_idx = np.flatnonzero(here_now)
            ad.set_true_speeds([self.sumo_ids[i] for i in act_idx], self.v_told[act_idx],
                               self.a_mean[act_idx])
        if not self.all_bg and self.active.any():
            self.subscribe_contexts()
        self.inserted = True
        if self.all_bg:
            ad.subscribe_departed()
        if ad.gui and self.active.any() and (self.followed is None or not self.active[self.followed]):
            self.followed = middle_member(self.active, self.along, self.slot_d_0)
            ad.follow(self.sumo_ids[self.followed])
