"""The vehicles near the members, read through SUMO's subscriptions.

A mixin of the SUMO adapter (sumo/adapter.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` (the libsumo or traci module) and
``tc`` (its constants) and imports no SUMO itself.
"""
from __future__ import annotations

from operator import itemgetter

import numpy as np

from .types import Neighbours, sumo_to_cog


def _nobody() -> Neighbours:
    """No neighbour (read-only empty arrays, shared between steps)."""
    e, i = np.empty(0), np.empty(0, dtype=int)
    e.flags.writeable = i.flags.writeable = False
    return Neighbours([], [], e, e, e, e, e, e, e, [], i)


NOBODY = _nobody()
"""No vehicle near the formation (shared between steps)."""


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
        self._neighbour_get = itemgetter(tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED,
                                         tc.VAR_ACCELERATION, tc.VAR_LANE_INDEX, tc.VAR_LANE_ID)
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

    def neighbour_rows(self, all_vehicles: bool):
        """Non-member vehicles from the context subscriptions (or from all subscriptions),
        sorted by id, in SUMO's frame (sumo/sense.py ``sense_step`` converts it into
        :class:`Neighbours`): ids, vTypes, front bumper (m, 2) [m], angle [deg], speed [m/s],
        acceleration [m/s^2], length [m], width [m], lane ids, lane index; None when there
        is none."""
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
        if not ids:  # nobody near the formation (often, ahead of the traffic)
            return None
        cols = list(zip(*map(self._neighbour_get, map(rows.__getitem__, ids))))
        bodies, body = self._bodies, self._body
        body = list(zip(*[bodies.get(vid) or body(vid) for vid in ids]))
        ang, v, a = np.array(cols[1:4], dtype=float)  # rows of one array: one conversion
        length, width = np.array(body[:2], dtype=float)
        return (ids, list(body[2]), np.array(cols[0], dtype=float), ang, v, a, length, width,
                list(cols[5]), np.array(cols[4], dtype=int))

    def vehicle_bodies(self, ids=None):
        """Every vehicle in SUMO (or those of ``ids``): ids, body centre x, y [m], heading
        [rad], length, width [m] (direct getters: used at insertion)."""
        v = self.api.vehicle
        ids = list(v.getIDList()) if ids is None else list(ids)
        n = len(ids)
        xf, yf, ang, length, width = (np.empty(n) for _ in range(5))
        for i, vid in enumerate(ids):
            xf[i], yf[i] = v.getPosition(vid)
            ang[i], length[i], width[i] = v.getAngle(vid), v.getLength(vid), v.getWidth(vid)
        x, y, psi = sumo_to_cog(xf, yf, ang, length / 2.0)
        return ids, x, y, psi, length, width

    def vehicles_on(self, edges) -> list[str]:
        """The vehicles on ``edges`` after the last step (ids)."""
        get = self.api.edge.getLastStepVehicleIDs
        return [vid for e in edges for vid in get(e)]
