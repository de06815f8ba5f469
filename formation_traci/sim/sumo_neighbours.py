"""The vehicles near the members, read through SUMO's subscriptions.

A mixin of the SUMO adapter (sim/sumo_adapter.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` (the libsumo or traci module) and
``tc`` (its constants) and imports no SUMO itself.
"""
from __future__ import annotations

from operator import itemgetter

import numpy as np

from .sumo_types import Neighbours, sumo_to_cog, sumo_to_cog_rows


class NeighbourReads:
    """Context subscription of the formation, subscriptions of every vehicle ('all'), and
    the rows they return as :class:`Neighbours` (one read per step, no per-vehicle call
    except the first sight of a vehicle, whose length, width and type are cached)."""

    api = tc = None
    members: dict
    _context: dict
    _subscribed: set
    _bodies: dict

    def subscribe_neighbours(self, vid: str, radius: float) -> None:
        """Context subscription: every vehicle within ``radius`` [m] of member ``vid`` (one per
        formation: overlapping subscriptions would return the same vehicles several times)."""
        tc = self.tc
        self.api.vehicle.subscribeContext(vid, tc.CMD_GET_VEHICLE_VARIABLE, radius, self._neighbour_vars())
        self._context[vid] = radius

    def _neighbour_vars(self):
        """Variables that change every step; length, width and type are read once per vehicle."""
        tc = self.tc
        return [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION, tc.VAR_LANE_ID,
                tc.VAR_LANE_INDEX]

    def _body(self, vid: str) -> tuple[float, float, str]:
        """Length [m], width [m] and vType of a vehicle (read on first sight, then cached)."""
        body = self._bodies.get(vid)
        if body is None:
            v = self.api.vehicle
            body = self._bodies[vid] = (v.getLength(vid), v.getWidth(vid), v.getTypeID(vid))
        return body

    def subscribe_departed(self) -> None:
        """Subscribe every vehicle that entered in the last step (recording 'all' vehicles);
        the first call also subscribes the vehicles already on the road."""
        if not getattr(self, "_subscribed_all", False):
            self._subscribed_all = True
            fresh = self.api.vehicle.getIDList()
        else:
            fresh = self.api.simulation.getDepartedIDList()
        for vid in fresh:
            if vid not in self.members:
                self.api.vehicle.subscribe(vid, self._neighbour_vars())
                self._subscribed.add(vid)

    def neighbours(self, all_vehicles: bool) -> Neighbours:
        """Non-member vehicles from the context subscriptions (or from all subscriptions),
        sorted by id."""
        if all_vehicles:
            rows = {vid: r for vid, r in self.api.vehicle.getAllSubscriptionResults().items() if r}
        else:
            ctx = self.api.vehicle.getAllContextSubscriptionResults()
            if len(ctx) == 1:
                rows = next(iter(ctx.values()))
            else:
                rows = {}
                for part in ctx.values():
                    rows.update(part)
        ids = sorted(rows.keys() - self.members.keys())
        tc = self.tc
        get = itemgetter(tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION,
                         tc.VAR_LANE_INDEX, tc.VAR_LANE_ID)
        cols = list(zip(*[get(rows[vid]) for vid in ids])) or [()] * 6
        bodies, body = self._bodies, self._body
        body = list(zip(*[bodies.get(vid) or body(vid) for vid in ids])) or [()] * 3
        xy = np.array(cols[0], dtype=float).reshape(-1, 2)
        ang, v, a = (np.array(c, dtype=float) for c in cols[1:4])
        li, lanes = np.array(cols[4], dtype=int), list(cols[5])
        length, width, types = np.array(body[0], dtype=float), np.array(body[1], dtype=float), list(body[2])
        x, y, psi = sumo_to_cog_rows(xy, ang, length * 0.5)  # centre of the body
        return Neighbours(ids, types, x, y, psi, v, a, length, width, lanes, li)

    def vehicle_bodies(self):
        """Every vehicle in SUMO: ids, body centre x, y [m], heading [rad], length, width [m]
        (direct getters: used once, at insertion)."""
        v = self.api.vehicle
        ids = list(v.getIDList())
        n = len(ids)
        xf, yf, ang, length, width = (np.empty(n) for _ in range(5))
        for i, vid in enumerate(ids):
            xf[i], yf[i] = v.getPosition(vid)
            ang[i], length[i], width[i] = v.getAngle(vid), v.getLength(vid), v.getWidth(vid)
        x, y, psi = sumo_to_cog(xf, yf, ang, length / 2.0)
        return ids, x, y, psi, length, width
