"""Join: a vehicle from the traffic taken over into a free slot, from where it is.

A join is due by its trigger; from then on, every step, the vehicles around the formation
are searched for one within ``reach`` [m] of the free slot (the joining member's slot) in
the slot's lane (its centre nearest to the centre of the slot's lane, SUMO's lane centres at
the slot, so that its path into the slot crosses no member's lane): the named SUMO vehicle,
or else the first of about the member's size (body length within SIZE_TOLERANCE_LENGTH, width
within SIZE_TOLERANCE_WIDTH of the member's) that drives centred in the lane (within
LANE_CENTRE_TOLERANCE of SUMO's lane centre: not in the middle of a lane change). The one
taken over starts its slot transition where it is, with its own rate
relative to the virtual car: the slot's offset is

    offset(t) = A + h(tau) (B - A) + r0 T g(tau),   g(tau) = tau - 6 tau^3 + 8 tau^4 - 3 tau^5,

(A its offset at the take-over, B the free slot, r0 = v_vehicle - v_vc along the road;
transition.py ``rate_basis``), so that at the take-over the desired point is where the
vehicle is and moves as it moves: the controller starts from a zero formation error, with
no jump. :func:`join_duration` is the shortest T that keeps the slot's acceleration and jerk
within the comfort limits (sampled peaks, searched upwards from min_duration; with r0 = 0 it
is transition_duration's within 2 %).
"""
from __future__ import annotations

import numpy as np

from ...road.lanes import LaneCentres
from .gap import Others
from .transition import ComfortLimits, quintic, rate_basis

SIZE_TOLERANCE_LENGTH = 1.0
"""A vehicle taken over without being named may be this much longer or shorter [m]."""
SIZE_TOLERANCE_WIDTH = 0.5
"""... and this much wider or narrower than the joining member [m]."""
LANE_CENTRE_TOLERANCE = 0.3
"""A vehicle farther than this from every lane centre is changing lanes: not taken [m]."""
_TAU = np.linspace(0.0, 1.0, 401)
_H, _H2 = np.array([quintic(x, 0.0, 1.0) for x in _TAU])[:, [0, 2]].T  # h(tau), h''(tau)
_G, _G2 = np.array([rate_basis(x, 0.0, 1.0) for x in _TAU])[:, [0, 2]].T  # g(tau), g''(tau)
_H3 = 60.0 * (1 - 6 * _TAU + 6 * _TAU ** 2)  # h'''(tau)
_G3 = -36.0 + _TAU * (192.0 - 180.0 * _TAU)  # g'''(tau)
T_STEP = 1.02
"""Search factor of :func:`join_duration` (the duration is at most 2 % above the shortest)."""
T_MAX = 120.0
"""Longest join transition searched [s]."""


def join_peaks(d: float, r0: float, T: float) -> tuple[float, float]:
    """Peak |acceleration| [m/s^2] and |jerk| [m/s^3] of offset(t) = d h(tau) + r0 T g(tau)
    over a transition of T [s] (displacement d [m], start rate r0 [m/s])."""
    acc = d * _H2 / T ** 2 + r0 * _G2 / T
    jerk = d * _H3 / T ** 3 + r0 * _G3 / T ** 2
    return float(np.max(np.abs(acc))), float(np.max(np.abs(jerk)))


def join_duration(d_along: float, d_across: float, r_along: float, r_across: float,
                  lim: ComfortLimits) -> float:
    """Shortest duration [s] (within T_STEP) of a join transition whose sampled peaks stay
    within ``lim``: along the road lon_accel / lon_jerk, across it lat_accel / lat_jerk."""
    T = lim.min_duration  # a start rate towards the slot can make it shorter than for r0 = 0
    while T < T_MAX:
        a_l, j_l = join_peaks(d_along, r_along, T)
        a_c, j_c = join_peaks(d_across, r_across, T)
        if (a_l <= lim.lon_accel and j_l <= lim.lon_jerk and a_c <= lim.lat_accel
                and j_c <= lim.lat_jerk):
            return T
        T *= T_STEP
    return T_MAX


def path_clearance(start, goal, shift: float, held, length: float, width: float, lengths,
                   widths) -> float:
    """Smallest clearance [m] between the joining vehicle (body ``length`` x ``width`` [m])
    on its real path, along = start + h (goal - start) + shift g, across = start + h (goal -
    start) (start, goal (2,) road frame [m]; shift = r0 T [m]), sampled over tau, and the
    members holding their slots ``held`` (k, 2) with bodies ``lengths``, ``widths``: per pair
    max(|d_along| - (L_i + L_j)/2, |d_across| - (W_i + W_j)/2), as assign.min_clearance."""
    held = np.asarray(held, float).reshape(-1, 2)
    if not len(held):
        return np.inf
    a = start[0] + _H * (goal[0] - start[0]) + shift * _G
    c = start[1] + _H * (goal[1] - start[1])
    da = np.abs(a[:, None] - held[None, :, 0]) - (length + np.asarray(lengths)[None, :]) / 2
    dc = np.abs(c[:, None] - held[None, :, 1]) - (width + np.asarray(widths)[None, :]) / 2
    return float(np.min(np.maximum(da, dc)))


def pick_vehicle(others: Others, s_slot: float, d_slot: float, reach: float, lanes: LaneCentres,
                 length: float, width: float, vehicle: str | None) -> int:
    """Index in ``others`` of the vehicle to take over into the slot at (s_slot, d_slot)
    [m] (centre arc length, lateral offset), or -1: none within ``reach`` [m] yet (see the
    module docstring; ``lanes``: SUMO's lane centres). The nearest one wins when several
    qualify."""
    if len(others.ids) == 0:
        return -1
    dist = np.hypot(others.s - s_slot, others.d - d_slot)
    ok = (dist <= reach) & lanes.same_lane(s_slot, others.d, d_slot)
    if vehicle is not None:
        ok &= np.array([vid == vehicle for vid in others.ids])
    else:
        ok &= np.abs(others.length - length) <= SIZE_TOLERANCE_LENGTH
        ok &= np.abs(others.width - width) <= SIZE_TOLERANCE_WIDTH
        ok &= lanes.off_centre(s_slot, others.d) <= LANE_CENTRE_TOLERANCE
    if not ok.any():
        return -1
    return int(np.flatnonzero(ok)[np.argmin(dist[ok])])


def without(others: Others, j: int) -> Others:
    """``others`` without entry j."""
    keep = np.arange(len(others.ids)) != j
    return Others(tuple(v for k, v in enumerate(others.ids) if k != j), others.s[keep],
                  others.d[keep], others.length[keep], others.width[keep], others.v[keep])


def describe(vid: str, gap: float, T: float, r0: float) -> str:
    """The maneuver_start detail of a join."""
    return (f"takes over {vid} {gap:.1f} m from the slot, closing speed {r0:+.2f} m/s, "
            f"T = {T:.2f} s")

