"""Setting SUMO up for the members and handing vehicles over: the network's friction, the
members' vehicle types, the release of a member to SUMO's own driver model, and (join) a
vehicle SUMO drives until a member takes it over.

A mixin of the SUMO adapter (sumo/adapter/__init__.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` (the libsumo or traci module) and imports
no SUMO itself.
"""
from __future__ import annotations

import numpy as np

from ..types import (LANE_CHANGE_MODE_DEFAULT, ORDINARY_CLASS, SPEED_MODE_DEFAULT, SPEED_MODE_DRIVEN,
                    MemberType, SumoError)


class VehicleSetup:
    """Friction, member vTypes and the hand-overs (see the module docstring)."""

    api = None
    members: dict
    _window: dict
    _member_lane: dict
    _overlap: dict
    _ends: dict
    _routes: dict
    _bodies: dict
    _subscribed: set

    def set_friction(self, mu: float) -> None:
        """Set the friction of every edge of the network [-] (SUMO's cars with the friction
        device slow down on slippery lanes). ``edge.setFriction``: the traci server rejects
        ``lane.setFriction`` in SUMO 1.28."""
        for edge in self.api.edge.getIDList():
            if not edge.startswith(":"):
                self.api.edge.setFriction(edge, mu)

    def forbid_lanes(self, lanes, vclasses) -> None:
        """Disallow vehicle classes on lanes (added to each lane's disallowed classes)."""
        for lane in lanes:
            have = list(self.api.lane.getDisallowed(lane))
            self.api.lane.setDisallowed(lane, sorted(set(have) | set(vclasses)))

    def know_route(self, route_id: str, edges: list[str]) -> None:
        """Keep a route SUMO already has (added by :meth:`add_route`, or in a loaded state)
        with its edges' lengths [m] for the members' route windows."""
        lengths = np.array([self.api.lane.getLength(f"{e}_0") for e in edges])
        self._routes[route_id] = (list(edges), lengths)

    def save_state(self, path) -> None:
        """SUMO's saved state (``simulation.saveState``; with ``--save-state.rng`` its random
        number generators too) into ``path`` (``.xml.gz``: compressed)."""
        self.api.simulation.saveState(str(path))

    def add_member_type(self, mt: MemberType, exists: bool = False) -> None:
        """The members' vType ``mt`` (``exists``: SUMO has it already, from a loaded state:
        its attributes are set again, the state keeps some with two decimals only)."""
        vt = self.api.vehicletype
        if not exists:
            vt.copy(mt.base, mt.id)
        vt.setLength(mt.id, mt.length)
        vt.setWidth(mt.id, mt.width)
        vt.setColor(mt.id, (*mt.color, 255))
        vt.setVehicleClass(mt.id, mt.vclass)
        vt.setMaxSpeed(mt.id, mt.max_speed)
        vt.setMinGap(mt.id, mt.min_gap)
        vt.setImperfection(mt.id, 0.0)
        vt.setSpeedDeviation(mt.id, 0.0)
        vt.setAccel(mt.id, mt.accel)
        vt.setDecel(mt.id, mt.decel)
        vt.setEmergencyDecel(mt.id, mt.emergency_decel)
        vt.setMaxSpeedLat(mt.id, 10.0)
        if mt.ssm_device:  # by the type, not --device.ssm.explicit: SUMO keeps that id list
            vt.setParameter(mt.id, "has.ssm.device", "true")  # from the first run of a process

    def release(self, vid: str, accel: float, decel: float, exit_edge: str = "") -> str:
        """Hand member ``vid`` over to SUMO's own driver model at its lane, position and
        speed: its route becomes the rest of the formation's route from its edge (or, with
        ``exit_edge``, SUMO's route to that edge: ``changeTarget``), its acceleration and
        deceleration ``accel`` / ``decel`` [m/s^2], SUMO's safe-speed and lane-change checks
        are on again (their default modes), and from now on it is an ordinary vehicle (a
        neighbour). Returns its lane id; raises SumoError when the exit cannot be reached."""
        v = self.api.vehicle
        window = self._window.pop(vid, None)
        lane = self._member_lane.pop(vid, "")
        self._overlap.pop(vid, None)
        self._ends.pop(vid, None)
        mt = self.members.get(vid)
        if mt is not None and mt.vclass in ORDINARY_CLASS:  # lanes closed to members open again
            v.setVehicleClass(vid, ORDINARY_CLASS[mt.vclass])
        if window is not None and lane and not lane.startswith(":"):
            edges = self._routes[window[0]][0]
            edge = lane.rsplit("_", 1)[0]
            if edge in edges:
                try:
                    v.setRoute(vid, edges[edges.index(edge):])
                except self.api.TraCIException:
                    pass  # keeps its window; SUMO reports it at the window's end
        if exit_edge:
            try:
                v.changeTarget(vid, exit_edge)
            except self.api.TraCIException as exc:
                raise SumoError(f"no route from {lane or 'its lane'} to the exit {exit_edge}: {exc}") from None
        v.setAccel(vid, accel)
        v.setDecel(vid, decel)
        v.setSpeed(vid, -1.0)  # the speed commanded with its moves no longer holds
        v.setSpeedMode(vid, SPEED_MODE_DEFAULT)
        v.setLaneChangeMode(vid, LANE_CHANGE_MODE_DEFAULT)
        self.members.pop(vid, None)
        return lane

    def add_driven(self, vid: str, edges: list[str], lane: int, pos: float, speed: float,
                   mt: MemberType, accel: float, decel: float) -> None:
        """A vehicle of type ``mt`` that SUMO drives: on ``edges[0]`` lane ``lane``, front
        bumper ``pos`` [m] from the edge's start, ``speed`` [m/s] (inserted as soon as SUMO
        finds it safe), acceleration / deceleration ``accel`` / ``decel`` [m/s^2], keeping
        its lane (lane-change mode 0). A joining member before the join takes it over."""
        rid = f"{vid}_entry"
        self.api.route.add(rid, list(edges))
        self.api.vehicle.add(vid, rid, typeID=mt.id, depart="now", departLane=str(int(lane)),
                             departPos=f"{max(pos, 0.0):.3f}", departSpeed=f"{max(speed, 0.0):.3f}")
        self.api.vehicle.setAccel(vid, accel)
        self.api.vehicle.setDecel(vid, decel)
        self.api.vehicle.setLaneChangeMode(vid, 0)

    def take_over(self, vid: str, mt: MemberType, route_id: str) -> None:
        """Join: SUMO vehicle ``vid`` becomes a member where it is: vType ``mt`` (SUMO keeps
        its front bumper where it is), no safe-speed or lane-change checks of its own, placed
        by moveToXY from the next step on along the formation's route ``route_id`` from its
        edge (the route window, as for an inserted member)."""
        self.members[vid] = mt
        self._bodies.pop(vid, None)
        v = self.api.vehicle
        v.setType(vid, mt.id)
        v.setSpeedMode(vid, 0)
        v.setLaneChangeMode(vid, 0)
        v.subscribe(vid, self._member_vars())  # replaces a neighbour subscription
        self._subscribed.add(vid)
        self._window[vid] = (route_id, -1)

    def drive_with_sumo(self, vid: str) -> None:
        """Member ``vid`` (inserted, placed once) is driven by its vType's own car-following
        model from now on (sumo/driven.py): SUMO's safe-speed and acceleration checks on, the
        right of way at junctions not (:data:`SPEED_MODE_DRIVEN`), lane changes off (it keeps
        its lane), no moveToXY."""
        self.api.vehicle.setSpeedMode(vid, SPEED_MODE_DRIVEN)
        self.api.vehicle.setLaneChangeMode(vid, 0)

    def driven_states(self, ids: list[str]):
        """SUMO's state of vehicles ``ids`` after the last step: front bumper (n, 2) [m], angle
        (n,) [deg, CW from north], speed (n,) [m/s], acceleration (n,) [m/s^2] (NaN for a
        vehicle SUMO no longer has)."""
        v = self.api.vehicle
        out = np.full((len(ids), 5), np.nan)
        for i, vid in enumerate(ids):
            try:
                out[i, :2] = v.getPosition(vid)
                out[i, 2:] = v.getAngle(vid), v.getSpeed(vid), v.getAcceleration(vid)
            except self.api.TraCIException:
                pass  # removed: read_members reports it
        return out[:, :2], out[:, 2], out[:, 3], out[:, 4]
