"""Traffic-aware virtual leader: time gaps to SUMO's vehicles ahead of the members.

Pure functions over arrays in road (Frenet) coordinates: s along the reference line [m],
d across it, left positive [m]. The virtual car's acceleration is the smallest of its
free-road speed law and a constant-time-gap law for every member; a member whose way to
its slot is blocked (a cut-in) gets its speed reference capped so it keeps a safe gap.
"""
from __future__ import annotations

import numpy as np
from numba import njit

K_SPEED = 0.5
"""Free-road speed law gain [1/s]: a = K (v_set - v) + v_set dot."""
K_GAP = 0.2
"""Gap-error gain of the time-gap law [1/s^2]."""
K_REL = 0.7
"""Relative-speed gain of the time-gap law [1/s]."""
B_COMFORT = 1.5
"""Braking [m/s^2] below which the constant-time-gap law alone handles a closing vehicle."""
LATERAL_MARGIN = 0.3
"""Vehicles whose bodies come closer than this sideways count as 'in the lane' [m]."""


def vehicles_ahead(m_s_front, m_d, m_half_w, o_s_rear, o_d, o_half_w, o_v):
    """Nearest other vehicle ahead of each member that overlaps it sideways.

    Parameters
    ----------
    m_s_front, m_d, m_half_w : ndarray, shape (n,)
        Members' front bumper arc length [m], lateral offset [m] and half width [m].
    o_s_rear, o_d, o_half_w, o_v : ndarray, shape (k,)
        Other vehicles' rear arc length [m], lateral offset [m], half width [m], speed [m/s].

    Returns
    -------
    gap : ndarray, shape (n,)
        Bumper-to-bumper gap [m] (inf when nobody is ahead).
    v_lead : ndarray, shape (n,)
        Speed of that vehicle [m/s] (nan when nobody is ahead).
    index : ndarray, shape (n,)
        Index of that vehicle in the other arrays (-1 when nobody is ahead).
    """
    m_s_front, m_d, m_half_w = (np.ascontiguousarray(a, dtype=np.float64) for a in (m_s_front, m_d, m_half_w))
    o = [np.ascontiguousarray(a, dtype=np.float64) for a in (o_s_rear, o_d, o_half_w, o_v)]
    return _vehicles_ahead(m_s_front, m_d, m_half_w, *o)


@njit(cache=True)
def _vehicles_ahead(m_s_front, m_d, m_half_w, o_s_rear, o_d, o_half_w, o_v):
    """Loop form of :func:`vehicles_ahead` (compiled: it runs every step over every pair)."""
    n, k = m_s_front.shape[0], o_s_rear.shape[0]
    gap = np.full(n, np.inf)
    v_lead = np.full(n, np.nan)
    index = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        for j in range(k):
            g = o_s_rear[j] - m_s_front[i]
            # a vehicle whose rear is at most 1 m behind our front is still 'ahead' (side by
            # side with a small overlap is a collision course, not a vehicle behind)
            if g > -1.0 and g < gap[i] and \
                    abs(o_d[j] - m_d[i]) < o_half_w[j] + m_half_w[i] + LATERAL_MARGIN:
                gap[i], v_lead[i], index[i] = g, o_v[j], j
    return gap, v_lead, index


def time_gap_accel(gap, v, v_lead, time_gap, min_gap):
    """Acceleration [m/s^2] that keeps gap -> min_gap + time_gap v behind a leader.

    Constant-time-gap law a = K_GAP (gap - g*) + K_REL (v_lead - v). When matching the
    leader's speed within the free gap needs more than B_COMFORT of braking,
    b = (v^2 - v_lead^2) / (2 (gap - min_gap)), the law is bounded above by -b (a far, slower
    vehicle needs no braking yet; a near one gets all it needs). +inf where there is no leader.
    """
    a = np.full(np.shape(gap), np.inf)
    has = np.isfinite(gap)
    if not np.any(has):
        return a
    g, vv, vl = gap[has], v[has], v_lead[has]
    law = K_GAP * (g - min_gap - time_gap * vv) + K_REL * (vl - vv)
    free = np.maximum(g - min_gap, 0.1)
    closing = np.maximum(vv * vv - vl * vl, 0.0)
    b_need = closing / (2.0 * free)
    law = np.where(b_need > B_COMFORT, np.minimum(law, -b_need), law)
    a[has] = law
    return a


def leader_accel(v_vc, v_set, v_set_dot, member_accels, accel_max, decel_emergency):
    """The virtual car's acceleration [m/s^2]: free-road law, limited by every member's gap law."""
    a = K_SPEED * (v_set - v_vc) + v_set_dot
    if len(member_accels):
        a = min(a, float(np.min(member_accels)))
    a = float(np.clip(a, -decel_emergency, accel_max))
    if v_vc <= 0.0 and a < 0.0:
        a = 0.0
    return a


def member_speed_cap(gap, v_lead, time_gap, min_gap):
    """Largest speed reference [m/s] for a member with a vehicle ``gap`` [m] ahead.

    The member may close in on the vehicle until the gap is min_gap + time_gap v_lead, with
    the gap error removed over ``time_gap``; inf where nobody is ahead.
    """
    cap = np.full(np.shape(gap), np.inf)
    has = np.isfinite(gap)
    cap[has] = np.maximum(v_lead[has] + (gap[has] - min_gap - time_gap * v_lead[has]) / time_gap, 0.0)
    return cap
