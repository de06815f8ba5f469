"""The vehicles on given lanes (an on-ramp's, for the yield law of control/merge.py) and where
every vehicle is (the measurement stretch's drain, sumo/sections.py).

A mixin of the SUMO adapter (sumo/adapter/__init__.py): it works on the adapter's ``api`` and imports no
SUMO itself. Read only while a formation is near a join (sumo/merge_watch.py), a few lanes a
step.
"""
from __future__ import annotations

import numpy as np


class RampReads:
    """Reads of the vehicles on given lanes (see the module docstring)."""

    api = None

    def ramp_vehicles(self, lanes: dict[str, float], skip) -> tuple[list[str], list[str], np.ndarray]:
        """The vehicles on ``lanes`` (lane id -> distance from its start to the join [m]) but
        those in ``skip`` (the members): their ids, lanes and a (5, m) array of rows: distance
        of the front bumper before the join [m] (negative past it), speed [m/s], length [m],
        time gap [s] (their vType's tau) and lane position [m]."""
        lane_api, veh = self.api.lane, self.api.vehicle
        ids, on, rows = [], [], []
        for lane_id, dist in lanes.items():
            for vid in lane_api.getLastStepVehicleIDs(lane_id):
                if vid in skip:
                    continue
                pos = veh.getLanePosition(vid)
                ids.append(vid)
                on.append(lane_id)
                rows.append((dist - pos, veh.getSpeed(vid), veh.getLength(vid), veh.getTau(vid), pos))
        out = np.array(rows, dtype=float).T if rows else np.empty((5, 0))
        return ids, on, out

    def vehicle_places(self, among=None) -> dict[str, tuple[str, float]]:
        """Edge and lane position [m] of every vehicle SUMO has (or of those of ``among`` it
        still has)."""
        veh = self.api.vehicle
        present = veh.getIDList()
        ids = present if among is None else set(present) & set(among)
        return {v: (veh.getRoadID(v), veh.getLanePosition(v)) for v in ids}
