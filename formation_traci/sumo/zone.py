"""Where the formation meets SUMO's traffic: the insertion zone cleared of SUMO's cars
(the same cars, at the same step, in a formation run and its twin) and the one context
subscription that reads the vehicles around the formation."""
from __future__ import annotations

import math

import numpy as np

from ..core.kernels import kernel
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


def insertion_zones(pos, heading, v, vehicles, front):
    """Every member's :func:`insertion_zone` as :func:`first_overlap` takes them: centres
    (n, 2) [m], headings (n,) [rad], lengths and widths (n, 2) [m]."""
    zones = [insertion_zone(pos[i], heading[i], v[i], vehicles[i], front[i]) for i in range(len(pos))]
    zc = np.array([z[0] for z in zones], dtype=float).reshape(-1, 2)
    zone_lw = np.array([(z[1], z[2]) for z in zones], dtype=float).reshape(-1, 2)
    return zc, np.asarray(heading, dtype=float), zone_lw


def blocker(zones, bodies) -> int:
    """The first of the ``bodies`` (x, y, heading, length, width arrays [m, rad]) that
    overlaps one of the ``zones`` (:func:`insertion_zones`), or -1 when none does."""
    if not len(zones[0]) or not len(bodies[0]):
        return -1
    return first_overlap(*zones, np.ascontiguousarray(np.array(bodies, dtype=float)))


@kernel
def first_overlap(zc, zh, zone_lw, bodies) -> int:
    """The first body (``bodies`` (5, m): x, y [m], heading [rad], length, width [m]) that
    overlaps some zone (centres ``zc`` (n, 2) [m], headings ``zh`` [rad], lengths and widths
    ``zone_lw`` (n, 2) [m]), or -1: :func:`_near`'s circle pre-test, then road_setup.py
    ``rectangles_overlap``'s separating-axis test, pair by pair."""
    for j in range(bodies.shape[1]):
        r_body = math.hypot(bodies[3, j], bodies[4, j]) / 2.0
        for i in range(zc.shape[0]):
            r_zone = math.hypot(zone_lw[i, 0], zone_lw[i, 1]) / 2.0
            dist = math.hypot(zc[i, 0] - bodies[0, j], zc[i, 1] - bodies[1, j])
            if dist <= r_zone + r_body + NEAR_MARGIN_M and _overlap(
                    (zc[i, 0], zc[i, 1], zh[i], zone_lw[i, 0], zone_lw[i, 1]),
                    (bodies[0, j], bodies[1, j], bodies[2, j], bodies[3, j], bodies[4, j])):
                return j
    return -1


@kernel
def _corners(r):
    """The corners (4, 2) [m] of rectangle ``r`` = (x, y, heading, length, width)."""
    c, s = math.cos(r[2]), math.sin(r[2])
    ax0, ax1 = c * r[3] / 2, s * r[3] / 2
    ay0, ay1 = -s * r[4] / 2, c * r[4] / 2
    out = np.empty((4, 2))
    out[0, 0], out[0, 1] = r[0] + ax0 + ay0, r[1] + ax1 + ay1
    out[1, 0], out[1, 1] = r[0] + ax0 - ay0, r[1] + ax1 - ay1
    out[2, 0], out[2, 1] = r[0] - ax0 - ay0, r[1] - ax1 - ay1
    out[3, 0], out[3, 1] = r[0] - ax0 + ay0, r[1] - ax1 + ay1
    return out


@kernel
def _overlap(r1, r2) -> bool:
    """Separating-axis test of two rectangles (x, y, heading, length, width) [m, rad]."""
    a, b = _corners(r1), _corners(r2)
    for h in (r1[2], r1[2] + np.pi / 2, r2[2], r2[2] + np.pi / 2):
        c, s = math.cos(h), math.sin(h)
        pa_min, pa_max, pb_min, pb_max = np.inf, -np.inf, np.inf, -np.inf
        for q in range(4):
            pa = a[q, 0] * c + a[q, 1] * s
            pb = b[q, 0] * c + b[q, 1] * s
            pa_min, pa_max = min(pa_min, pa), max(pa_max, pa)
            pb_min, pb_max = min(pb_min, pb), max(pb_max, pb)
        if pa_max <= pb_min or pb_max <= pa_min:
            return False
    return True
