"""Where the formation meets SUMO's traffic: the insertion zone cleared of SUMO's cars
(the same cars, at the same step, in a formation run and its twin) and the one context
subscription that reads the vehicles around the formation."""
from __future__ import annotations

import math

import numpy as np

from .road_setup import rectangles_overlap
from .sumo_plan import INSERT_CLEAR_TIME


def middle_member(active, along, across) -> int:
    """Index of the active member nearest the middle of the formation."""
    idx = np.flatnonzero(active)
    centre = np.array([along[idx].mean(), across[idx].mean()])
    return int(idx[np.argmin(np.hypot(along[idx] - centre[0], across[idx] - centre[1]))])


def subscribe_context(adapter, ids, active, along, across, radius):
    """One context subscription for the whole formation: on the active member nearest the
    middle of the formation, with the radius grown by the formation's extent around it.
    Returns that member's index."""
    idx = np.flatnonzero(active)
    owner = middle_member(active, along, across)
    extent = float(np.max(np.hypot(along[idx] - along[owner], across[idx] - across[owner])))
    adapter.subscribe_neighbours(ids[owner], radius + extent)
    return owner


def clear_insertion_zone(adapter, rec, t, pos, heading, v, vehicles, front):
    """Remove SUMO vehicles that stand where a member (chassis ``vehicles[i]``) is inserted,
    or inside its time gap ahead (``front`` [m]) or within INSERT_CLEAR_TIME of its speed
    behind it."""
    ids, x, y, psi, length, width = adapter.vehicle_bodies()
    for j, vid in enumerate(ids):
        for i in range(len(pos)):
            back = max(2.0, v[i] * INSERT_CLEAR_TIME)
            veh = vehicles[i]
            zone_len = veh.length + front[i] + back
            shift = (front[i] - back) / 2
            zc = pos[i] + shift * np.array([math.cos(heading[i]), math.sin(heading[i])])
            if rectangles_overlap(zc, heading[i], np.array([x[j], y[j]]), psi[j], zone_len, veh.width + 0.6,
                                  length[j], width[j]):
                adapter.remove_vehicle(vid)
                rec.add_event(t, "cleared_at_insertion", vid, "", "removed: it stood where a member is inserted")
                break
