"""Setting SUMO up for the members and handing them back: the network's friction, the
members' vehicle types, and the release of a member to SUMO's own driver model.

A mixin of the SUMO adapter (sim/sumo_adapter.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` (the libsumo or traci module) and imports
no SUMO itself.
"""
from __future__ import annotations

from .sumo_types import LANE_CHANGE_MODE_DEFAULT, SPEED_MODE_DEFAULT, MemberType


class VehicleSetup:
    """Friction, member vTypes and the hand-over of a member (see the module docstring)."""

    api = None
    members: dict
    _window: dict
    _member_lane: dict
    _overlap: dict
    _routes: dict

    def set_friction(self, mu: float) -> None:
        """Set the friction of every edge of the network [-] (SUMO's cars with the friction
        device slow down on slippery lanes). ``edge.setFriction``: the traci server rejects
        ``lane.setFriction`` in SUMO 1.28."""
        for edge in self.api.edge.getIDList():
            if not edge.startswith(":"):
                self.api.edge.setFriction(edge, mu)

    def add_member_type(self, mt: MemberType) -> None:
        vt = self.api.vehicletype
        vt.copy("DEFAULT_VEHTYPE", mt.id)
        vt.setLength(mt.id, mt.length)
        vt.setWidth(mt.id, mt.width)
        vt.setColor(mt.id, (*mt.color, 255))
        vt.setVehicleClass(mt.id, mt.vclass)
        vt.setMaxSpeed(mt.id, mt.max_speed)
        vt.setMinGap(mt.id, 0.5)
        vt.setImperfection(mt.id, 0.0)
        vt.setSpeedDeviation(mt.id, 0.0)
        vt.setAccel(mt.id, 10.0)
        vt.setDecel(mt.id, 10.0)
        vt.setEmergencyDecel(mt.id, 12.0)
        vt.setMaxSpeedLat(mt.id, 10.0)
        if mt.ssm_device:  # by the type, not --device.ssm.explicit: SUMO keeps that id list
            vt.setParameter(mt.id, "has.ssm.device", "true")  # from the first run of a process

    def release(self, vid: str, accel: float, decel: float) -> str:
        """Hand member ``vid`` over to SUMO's own driver model at its lane, position and
        speed: its route becomes the rest of the formation's route from its edge, its
        acceleration and deceleration ``accel`` / ``decel`` [m/s^2], SUMO's safe-speed and
        lane-change checks are on again (their default modes), and from now on it is an
        ordinary vehicle (a neighbour). Returns its lane id."""
        v = self.api.vehicle
        window = self._window.pop(vid, None)
        lane = self._member_lane.pop(vid, ("", -1, 0.0))[0]
        self._overlap.pop(vid, None)
        if window is not None and lane and not lane.startswith(":"):
            edges = self._routes[window[0]][0]
            edge = lane.rsplit("_", 1)[0]
            if edge in edges:
                try:
                    v.setRoute(vid, edges[edges.index(edge):])
                except self.api.TraCIException:
                    pass  # keeps its window; SUMO reports it at the window's end
        v.setAccel(vid, accel)
        v.setDecel(vid, decel)
        v.setSpeedMode(vid, SPEED_MODE_DEFAULT)
        v.setLaneChangeMode(vid, LANE_CHANGE_MODE_DEFAULT)
        self.members.pop(vid, None)
        return lane
