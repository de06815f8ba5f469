"""Formation flows on the SUMO side (sumo/formation_flows.py has the rule): is there room for a
due formation, and the counts of formations requested and inserted (run.json
``formation_flows``)."""
from __future__ import annotations

import numpy as np

from .zone import blocker, insertion_zones

LOOK_BEHIND_M, LOOK_AHEAD_M = 150.0, 250.0
"""The stretch around a due formation's members whose vehicles may block its entry [m]."""


class RoomCheck:
    """Is there room for a due formation (:meth:`__call__`)? The members' kinematics and each
    edge's vehicles with their poses are read once per step and state, however many
    formations of flows are due in it (their checks share a step's reads: SUMO's vehicles do
    not move between them). A formation that found no room keeps the vehicle that blocked it:
    while that vehicle still overlaps its zones from an edge the check reads, the answer is
    no without reading the others (the same answer: any overlap blocks)."""

    def __init__(self, world):
        self.world = world
        segs = world.plan.road.segments
        self._s0 = np.array([g.s0 for g in segs], dtype=float)
        self._s1 = np.array([g.s1 for g in segs], dtype=float)
        self._edges = [g.edge for g in segs]
        self._key = None  # (t, the state) of the reads below
        self._kin = self._on = None
        self._zones: dict[int, tuple] = {}  # first row -> (poses' bytes, near edges, zones)
        self._blocked_by: dict[int, str] = {}  # first row -> the vehicle that blocked it last

    def _step(self, t: float, state) -> None:
        key = (t, id(state))
        if key != self._key:
            fleet = self.world.fleet
            pos, _, heading = fleet.kinematics(state)
            self._key, self._kin = key, (pos, heading, fleet.speed(state))
            self._on = {}

    def _bodies(self, edges):
        """ids, x, y, heading, length, width of the vehicles on ``edges`` (sumo/adapter
        vehicle_bodies' rows; each edge read once per step)."""
        ad, on = self.world.adapter, self._on
        parts = []
        for e in edges:
            got = on.get(e)
            if got is None:
                got = on[e] = ad.vehicle_bodies(ad.vehicles_on((e,)))
            parts.append(got)
        if not parts:
            return [], *((np.empty(0),) * 5)
        return [vid for p in parts for vid in p[0]], *(np.concatenate(c) for c in list(zip(*parts))[1:])

    def _zones_of(self, rows: slice):
        """The edges to read and the insertion zones (sumo/zone.py ``insertion_zones``) of the
        members ``rows`` at their state's poses (kept while the poses and speeds stay)."""
        world = self.world
        pos, heading, v_all = self._kin
        idx = np.arange(rows.start, rows.stop)
        key = pos[idx].tobytes() + heading[idx].tobytes() + v_all[idx].tobytes()
        got = self._zones.get(rows.start)
        if got is not None and got[0] == key:
            return got[1], got[2]
        s = world.line.to_frenet(pos[idx])[0]
        lo, hi = float(np.min(s)) - LOOK_BEHIND_M, float(np.max(s)) + LOOK_AHEAD_M
        near = [self._edges[i] for i in np.flatnonzero((self._s1 >= lo) & (self._s0 <= hi))]
        ld, v = world.sc.leader, v_all[idx]
        zones = insertion_zones(pos[idx], heading[idx], v, [world.plan.vehicles[i] for i in idx],
                                ld.min_gap + ld.time_gap * v)
        self._zones[rows.start] = (key, near, zones)
        return near, zones

    def _still_blocks(self, vid: str, near, zones) -> bool:
        """Does vehicle ``vid`` still overlap ``zones`` from one of the edges ``near``?"""
        ad = self.world.adapter
        if ad.road_of(vid) not in near:  # not on them, or SUMO no longer has it
            return False
        return blocker(zones, ad.vehicle_bodies([vid])[1:]) >= 0

    def __call__(self, t: float, rows: slice, state) -> bool:
        """Are the insertion zones (sumo/zone.py ``insertion_zone``) of the members ``rows``
        at their state's poses free of SUMO's vehicles and of the members of the run that SUMO
        does not have yet?"""
        world = self.world
        self._step(t, state)
        near, zones = self._zones_of(rows)
        last = self._blocked_by.pop(rows.start, None)
        if last is not None and self._still_blocks(last, near, zones):
            self._blocked_by[rows.start] = last
            return False
        ids, x, y, psi, length, width = self._bodies(near)
        j = blocker(zones, (x, y, psi, length, width))
        if j >= 0:
            self._blocked_by[rows.start] = ids[j]
            return False
        own = np.flatnonzero(world.active & ~world.in_sumo)  # spawned, not inserted yet
        own = own[(own < rows.start) | (own >= rows.stop)]
        room = not len(own) or self._own_room(own, zones)
        if room:  # it enters: its zones are not asked for again
            self._zones.pop(rows.start, None)
        return room

    def _own_room(self, own, zones) -> bool:
        """Are ``zones`` free of the run's members ``own`` (not in SUMO yet)?"""
        world = self.world
        pos, heading, _ = self._kin
        mt = [world.mtypes[i] for i in own]
        shift = np.array([m.d_front - m.length / 2 for m in mt])  # CoG -> body centre [m]
        return blocker(zones, (pos[own, 0] + shift * np.cos(heading[own]),
                               pos[own, 1] + shift * np.sin(heading[own]), heading[own],
                               np.array([m.length for m in mt]), np.array([m.width for m in mt]))) < 0


def counted_entry(plan, inserted: dict, rows) -> None:
    """Count a formation of a flow entering (``rows``: its members' fleet rows)."""
    first = int(np.atleast_1d(rows)[0])
    for setup, _, r in plan.formations:
        if setup.flow and r.start == first:
            inserted[setup.flow] = inserted.get(setup.flow, 0) + 1


def flow_counts(plan, inserted: dict, t_end: float, departures, t0: float) -> dict:
    """run.json ``formation_flows``: per flow, the formations due by ``t_end`` [s] (requested)
    and those that entered (inserted), the members that entered, and for a penetration flow
    the share of formation vehicles among all that entered during the run (its members and
    the ``of_flow`` traffic flow's vehicles SUMO inserted after the warm-up ``t0`` [s])."""
    out, of_flow = {}, plan.flow_share_of
    for setup, p, _ in plan.formations:
        if setup.flow:
            c = out.setdefault(setup.flow, {"requested": 0, "inserted": inserted.get(setup.flow, 0),
                                            "members_inserted": 0})
            c["requested"] += int(setup.depart <= t_end + 1e-9)
            c["members_per_formation"] = len(p.ids)
    for c in out.values():
        c["members_inserted"] = c["inserted"] * c.pop("members_per_formation")
    for src in set(of_flow.values()) - {""}:  # the flows that take a share of traffic flow src
        shares = [fid for fid in out if of_flow.get(fid) == src]
        n = sum(1 for vid, t in departures if t >= t0 and vid.rsplit(".", 1)[0] == src)
        members = sum(out[fid]["members_inserted"] for fid in shares)
        for fid in shares:  # each flow's members among all vehicles that entered for src
            out[fid]["share"] = out[fid]["members_inserted"] / max(1, members + n)
            out[fid]["of_flow_vehicles"] = n
    return out
