"""The vehicles near the members, read through SUMO's subscriptions.

A mixin of the SUMO adapter (sumo/adapter/__init__.py, the only module that imports
libsumo/traci): it works on the adapter's ``api`` (the libsumo or traci module) and
``tc`` (its constants) and imports no SUMO itself.
"""
from __future__ import annotations


import numpy as np

from ..types import Neighbours, sumo_to_cog


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

    api = tc = native = None
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
        self._nb_keys = (tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION,
                         tc.VAR_LANE_INDEX, tc.VAR_LANE_ID)
        return [tc.VAR_POSITION, tc.VAR_ANGLE, tc.VAR_SPEED, tc.VAR_ACCELERATION, tc.VAR_LANE_ID,
                tc.VAR_LANE_INDEX]

    def _body(self, vid: str) -> tuple[float, float, str]:
        """Length [m], width [m] and vType of a vehicle (read on first sight, then cached)."""
        body = self._bodies.get(vid)
        if body is None:
            if self.native is not None:  # one cache with the C++ reads': the same first sight
                body = self._bodies[vid] = self.native.body(vid)
            else:
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
        is none (:meth:`neighbour_table`'s columns as arrays of their own)."""
        got = self.neighbour_table(all_vehicles)
        if got is None:
            return None
        ids, types, lane_ids, tb, lane_index = got
        front = np.ascontiguousarray(tb[:, :2])
        ang, v, a, length, width = np.ascontiguousarray(tb[:, 2:].T)  # rows of one copy
        return ids, types, front, ang, v, a, length, width, lane_ids, lane_index

    def neighbour_table(self, all_vehicles: bool, native: bool = False):
        """:meth:`neighbour_rows` as (ids, vTypes, lane ids, table (m, 7) of front bumper x, y
        [m], angle [deg], speed [m/s], acceleration [m/s^2], length, width [m], lane index
        (m,)); one conversion of the subscription rows (sumo/fused_path.py, with ``native``
        through the C++ reads of sumo/adapter/native_reads.py when they are there: the same rows),
        None when no vehicle is near. Every vehicle (``all_vehicles``: a twin, or a run that
        records every vehicle) is read through the C++ reads whenever they are there, on every
        path (tests/test_native_reads.py compares them with this SWIG extraction)."""
        if self.native is not None and (all_vehicles or native):
            if all_vehicles:
                return self.native.all_table(self.members)
            return self.native.neighbour_table(sorted(self._context), self.members)
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
        members = self.members
        ids = [vid for vid in rows if vid not in members]
        if not ids:  # nobody near the formation (often, ahead of the traffic)
            return None
        ids.sort()  # one context subscription's rows come sorted already: a linear pass
        recs = list(map(rows.__getitem__, ids))
        bodies, body = self._bodies, self._body
        bods = [bodies.get(vid) or body(vid) for vid in ids]
        pos, ang, speed, acc, index, lane = self._nb_keys
        tb = np.array([(*r[pos], r[ang], r[speed], r[acc], b[0], b[1]) for r, b in zip(recs, bods)],
                      dtype=float)
        return (ids, [b[2] for b in bods], [r[lane] for r in recs], tb,
                np.array([r[index] for r in recs], dtype=np.int64))

    def vehicle_bodies(self, ids=None):
        """Every vehicle in SUMO (or those of ``ids``): ids, body centre x, y [m], heading
        [rad], length, width [m] (direct getters: used at insertion)."""
        v = self.api.vehicle
        ids = list(v.getIDList()) if ids is None else list(ids)
        n = len(ids)
        if self.native is not None:  # the same getters, in one C++ call
            xf, yf, ang, length, width = self.native.poses(ids).T
        else:
            xf, yf, ang, length, width = (np.empty(n) for _ in range(5))
            for i, vid in enumerate(ids):
                xf[i], yf[i] = v.getPosition(vid)
                ang[i], length[i], width[i] = v.getAngle(vid), v.getLength(vid), v.getWidth(vid)
        x, y, psi = sumo_to_cog(xf, yf, ang, length / 2.0)
        return ids, x, y, psi, length, width

    def road_of(self, vid: str) -> str | None:
        """The edge vehicle ``vid`` is on (``""``: off the road; None: SUMO no longer has it)."""
        try:
            return self.api.vehicle.getRoadID(vid)
        except self.api.TraCIException:
            return None

    def vehicles_on(self, edges) -> list[str]:
        """The vehicles on ``edges`` after the last step (ids)."""
        get = self.api.edge.getLastStepVehicleIDs
        return [vid for e in edges for vid in get(e)]
