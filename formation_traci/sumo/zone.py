"""Where the formation meets SUMO's traffic: the insertion zone cleared of SUMO's cars
(the same cars, at the same step, in a formation run and its twin) and the one context
subscription that reads the vehicles around the formation."""
from __future__ import annotations

import math

import numpy as np

from .road_setup import rectangles_overlap
from .plan import INSERT_CLEAR_TIME

NEAR_MARGIN_M = 1e-6
"""Slack [m] of the circle pre-test of :func:`_near` (round-off of the corners: a pair the
exact test could see overlapping is never skipped)."""


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


def insertion_zone(pos, heading, v, veh, front):
    """The free space a member (chassis ``veh``) needs where it is inserted at CoG ``pos`` [m],
    ``heading`` [rad] and speed ``v`` [m/s]: its body, ``front`` [m] ahead of it and
    INSERT_CLEAR_TIME of its speed (at least 2 m) behind it, 0.3 m beside it. Returns (centre,
    length, width) [m] of that rectangle, aligned with ``heading``."""
    back = max(2.0, v * INSERT_CLEAR_TIME)
    shift = (front - back) / 2
    zc = pos + shift * np.array([math.cos(heading), math.sin(heading)])
    return zc, veh.length + front + back, veh.width + 0.6


def _near(zones, x, y, length, width) -> np.ndarray:
    """(zones, vehicles) bool: the circles around each zone and each vehicle's body meet (a
    pair whose circles are apart cannot overlap: the exact test is skipped for it)."""
    zc = np.array([z[0] for z in zones]).reshape(-1, 2)
    r_zone = np.array([math.hypot(z[1], z[2]) / 2.0 for z in zones])
    r_body = np.hypot(length, width) / 2.0
    dist = np.hypot(zc[:, :1] - x[None, :], zc[:, 1:] - y[None, :])
    return dist <= r_zone[:, None] + r_body[None, :] + NEAR_MARGIN_M


def clear_insertion_zone(adapter, rec, t, pos, heading, v, vehicles, front):
    """Remove SUMO vehicles that stand where a member (chassis ``vehicles[i]``) is inserted,
    or inside its time gap ahead (``front`` [m]) or within INSERT_CLEAR_TIME of its speed
    behind it (:func:`insertion_zone`)."""
    ids, x, y, psi, length, width = adapter.vehicle_bodies()
    zones = [insertion_zone(pos[i], heading[i], v[i], vehicles[i], front[i]) for i in range(len(pos))]
    if not zones or not len(ids):
        return
    near = _near(zones, x, y, length, width)
    for j in np.flatnonzero(near.any(axis=0)):
        vid = ids[j]
        for i in np.flatnonzero(near[:, j]):
            zc, zone_len, zone_w = zones[i]
            if rectangles_overlap(zc, heading[i], np.array([x[j], y[j]]), psi[j], zone_len, zone_w,
                                  length[j], width[j]):
                adapter.remove_vehicle(vid)
                rec.add_event(t, "cleared_at_insertion", vid, "", "removed: it stood where a member is inserted")
                break


def has_room(pos, heading, v, vehicles, front, bodies) -> bool:
    """Is every member's :func:`insertion_zone` free of the ``bodies`` (x, y, heading, length,
    width arrays [m, rad] of the vehicles that could be there)?"""
    x, y, psi, length, width = bodies
    zones = [insertion_zone(pos[i], heading[i], v[i], vehicles[i], front[i]) for i in range(len(pos))]
    if not zones or not len(x):
        return True
    for i, j in zip(*np.nonzero(_near(zones, np.asarray(x), np.asarray(y), np.asarray(length),
                                      np.asarray(width)))):
        zc, zone_len, zone_w = zones[i]
        if rectangles_overlap(zc, heading[i], np.array([x[j], y[j]]), psi[j], zone_len, zone_w,
                              length[j], width[j]):
            return False
    return True
