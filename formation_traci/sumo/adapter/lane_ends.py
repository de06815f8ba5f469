"""Members on lanes that do not lead on for them: the lane SUMO has a member on when it moves it
across a lane's end.

SUMO moves a vehicle placed by ``moveToXY`` during its step along the lane it had (by the
distance along its route to the new place) and only then puts it where ``moveToXY`` asked
(``MSVehicle::executeMove``, ``Influencer::postProcessRemoteControl``). On a lane with no
connection the member may use into the next edge of its route (LuST's on-ramp edges: lane 1
runs on geometrically as lane 0 of the next edge, but its own connection leads sideways into
lane 1 and is closed to the members, road/lanes.py ``sideways_internal_lanes``) that move
crosses the lane's end with no link to follow: SUMO reports "emergency stop at the end of lane
... no connection to the next edge" and stops the member for the step. So in the step in which
a member crosses the end of such a lane it is first put (``moveTo``) at the start of the lane it
enters where it geometrically is: the internal lane, open to it, that ends across from the end
of its lane (LuST: the ramp's ``_0_0`` into lane 0). A lane that simply ends (an acceleration
lane, a dropped lane) has none: a member that only reaches into such a lane is not put on it
(sumo/adapter/__init__.py ``place``) while it crosses its end.

A mixin of the SUMO adapter (sumo/adapter/__init__.py): it works on the adapter's ``api`` and member
bookkeeping and imports no SUMO itself. docs/sumo.md, "Lanes that end for a member".
"""
from __future__ import annotations

import math

CROSS_MARGIN_M = 1.0
"""A member whose front bumper, moved on by its speed times the step, comes within this of its
lane's end is taken to cross it in the coming step [m]. Put on the next lane a step early it is
put back on its lane by the ``moveToXY`` of that step (SUMO moves it by nothing then)."""
JOINT_REACH_M = 30.0
"""The lane entered must end at most this far ahead of the end of the member's lane [m]."""


class LaneEnds:
    """Per member the lane end it must not cross in SUMO (see the module docstring)."""

    api = None
    members: dict
    _window: dict
    _routes: dict
    _ends: dict  # member -> (length of its lane [m], the lane it enters at its end or '')
    _end_of: dict  # (lane, vClass, next edge) -> (length [m], lane entered or '') or None
    _dt: float = math.nan

    def _track_end(self, vid: str, lane: str) -> None:
        """Keep in :attr:`_ends` whether member ``vid``'s lane ``lane`` leads on for it."""
        end = self._lane_end(vid, lane)
        if end is None:
            self._ends.pop(vid, None)
        else:
            self._ends[vid] = end

    def _lane_end(self, vid: str, lane: str):
        """(length [m], lane entered or '') when ``lane`` has no connection member ``vid`` may
        use into the next edge of its route; None when it has one (or is internal, or the last)."""
        window = self._window.get(vid)
        mt = self.members.get(vid)
        if not lane or lane.startswith(":") or window is None or mt is None:
            return None
        edges = self._routes[window[0]][0]
        edge = lane.rsplit("_", 1)[0]
        try:
            nxt = edges[edges.index(edge, max(window[1], 0)) + 1]
        except (ValueError, IndexError):
            return None
        key = (lane, mt.vclass, nxt)
        if key not in self._end_of:
            self._end_of[key] = self._find_end(lane, mt.vclass, nxt)
        return self._end_of[key]

    def _open(self, link, vclass: str) -> bool:
        """May ``vclass`` use the link (its internal lane, or the lane it leads into)?"""
        return vclass not in self.api.lane.getDisallowed(link[4] or link[0])

    def _find_end(self, lane: str, vclass: str, nxt: str):
        links = [k for k in self.api.lane.getLinks(lane) if k[0].rsplit("_", 1)[0] == nxt]
        if any(self._open(k, vclass) for k in links):
            return None
        ln = self.api.lane
        shape = ln.getShape(lane)
        (x0, y0), (x1, y1) = shape[-2][:2], shape[-1][:2]
        n = math.hypot(x1 - x0, y1 - y0) or 1.0
        tx, ty = (x1 - x0) / n, (y1 - y0) / n
        edge = lane.rsplit("_", 1)[0]
        best, best_lat = "", 0.5 * ln.getWidth(lane)
        for k in range(self.api.edge.getLaneNumber(edge)):
            for link in ln.getLinks(f"{edge}_{k}"):
                if link[0].rsplit("_", 1)[0] != nxt or not link[4] or not self._open(link, vclass):
                    continue
                ex, ey = ln.getShape(link[4])[-1][:2]
                along, lat = (ex - x1) * tx + (ey - y1) * ty, abs(-(ex - x1) * ty + (ey - y1) * tx)
                if -2.0 <= along <= JOINT_REACH_M and lat < best_lat:
                    best, best_lat = link[4], lat
        return ln.getLength(lane), best

    def _reaches_end(self, vid: str, length: float, v: float) -> bool:
        """Does member ``vid``'s front bumper, moved on at ``v`` [m/s] for a step, come within
        :data:`CROSS_MARGIN_M` of the end of its lane of length ``length`` [m]?"""
        if math.isnan(self._dt):
            self._dt = self.api.simulation.getDeltaT()
        return self.api.vehicle.getLanePosition(vid) + v * self._dt >= length - CROSS_MARGIN_M

    def _cross_end(self, vid: str, v: float, hint: str | None) -> str | None:
        """Before member ``vid``'s move at speed ``v`` [m/s]: when it crosses the end of its lane
        in this step, put it at the start of the lane it enters; returns the neighbour lane to
        hint (``hint``, or None when that lane does not lead on for it and it reaches its end)."""
        end = self._ends.get(vid)
        if end is not None and end[1] and self._reaches_end(vid, end[0], v):
            try:
                self.api.vehicle.moveTo(vid, end[1], 0.0)
                return None
            except self.api.TraCIException:
                pass  # SUMO reports the lane end as before
        if hint is not None:
            other = self._lane_end(vid, hint)
            if other is not None and self._reaches_end(vid, other[0], v):
                return None
        return hint
