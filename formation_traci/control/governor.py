"""Traffic-aware virtual leader: time gaps to SUMO's vehicles ahead of the members.

Pure functions over arrays in road (Frenet) coordinates: s along the reference line [m],
d across it, left positive [m]. The virtual car's acceleration is the smallest of its
free-road speed law and a constant-time-gap law for every member; a member whose way to
its slot is blocked (a cut-in) gets its speed reference capped so it keeps a safe gap.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel

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


TIME_GAP, MIN_GAP, ACCEL_MAX, DECEL_EMERGENCY, DECEL_FOLLOW, DECEL_MAX, TRAFFIC_AWARE = range(7)
"""Slots of the packed governor limits (control/reference_road.py GovernorLimits.packed):
time gap [s], minimum gap [m], largest acceleration, emergency deceleration, largest braking
outside emergencies, comfortable deceleration [m/s^2], traffic-aware 1/0."""


@kernel(error_model="python")
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
    vehicle needs no braking yet; a near one gets all it needs). A leader at least as fast as
    the member (a faster car cutting in close) opens the gap by itself: the law is then bounded
    below by -B_COMFORT (the gap error is removed comfortably, never as an emergency).
    +inf where there is no leader.
    """
    gap, v, v_lead = (np.array(a) for a in np.broadcast_arrays(  # own writeable copies: the kernel's
        *(np.asarray(x, dtype=np.float64) for x in (gap, v, v_lead))))  # compiled types, no read-only view
    out = np.empty(gap.shape)
    _gap_laws(gap.ravel(), v.ravel(), v_lead.ravel(), float(time_gap), float(min_gap), out.reshape(-1))
    return out


@kernel(error_model="python")
def _need(gap, v, v_lead, min_gap):
    """The constant deceleration [m/s^2] that matches the leader's speed within the free gap
    gap - min_gap [m] (at most 0 behind a leader at least as fast)."""
    return (v * v - v_lead * v_lead) / (2.0 * max(gap - min_gap, 0.1))


@kernel(error_model="python")
def _closing_bound(law, gap, v, v_lead, min_gap):
    """The bounds of :func:`time_gap_accel` on a gap law's acceleration ``law`` [m/s^2]: at
    most -b_need when matching the leader's speed within gap - min_gap needs more than
    B_COMFORT; otherwise (a leader at least as fast, or one so little slower that comfortable
    braking matches its speed in time: a cut-in at nearly the member's speed) at least
    -B_COMFORT, the gap error removed comfortably."""
    b_need = _need(gap, v, v_lead, min_gap)
    if b_need > B_COMFORT:
        return min(law, -b_need)
    return max(law, -B_COMFORT)


@kernel(error_model="python")
def _gap_law(gap, v, v_lead, time_gap, min_gap):
    """:func:`time_gap_accel` for one member."""
    if not np.isfinite(gap):
        return np.inf
    law = K_GAP * (gap - min_gap - time_gap * v) + K_REL * (v_lead - v)
    return _closing_bound(law, gap, v, v_lead, min_gap)


@kernel(error_model="python")
def _gap_laws(gap, v, v_lead, time_gap, min_gap, out):
    for i in range(gap.shape[0]):
        out[i] = _gap_law(gap[i], v[i], v_lead[i], time_gap, min_gap)


def leader_accel(v_vc, v_set, v_set_dot, member_accels, accel_max, decel_emergency,
                 decel_follow=np.inf, decel_comfort=np.inf):
    """The virtual car's acceleration [m/s^2]: free-road law, limited by every member's gap
    law; braking that is not an emergency (not below ``-decel_comfort``) at most
    ``decel_follow``: what every member's speed loop can follow (a mixed formation)."""
    acc = np.ascontiguousarray(member_accels, dtype=np.float64)
    return _leader_law(float(v_vc), float(v_set), float(v_set_dot), acc, np.ones(acc.shape[0], np.bool_),
                       float(accel_max), float(decel_emergency), float(decel_follow),
                       float(decel_comfort))


@kernel(error_model="python")
def _leader_law(v_vc, v_set, v_set_dot, member_accels, use, accel_max, decel_emergency,
                decel_follow, decel_comfort):
    a = max(K_SPEED * (v_set - v_vc) + v_set_dot, -decel_follow)  # the set speed: never an emergency
    for i in range(member_accels.shape[0]):
        if use[i]:
            a = min(a, member_accels[i])
    if a >= -decel_comfort:  # not an emergency: no harder than every member can follow
        a = max(a, -decel_follow)
    a = min(max(a, -decel_emergency), accel_max)
    if v_vc <= 0.0 and a < 0.0:
        a = 0.0
    return a


@kernel(error_model="python")
def free_road_accel(v_vc, v_set, v_set_dot, accel_max, decel_emergency, decel_follow,
                    decel_comfort):
    """The virtual car's acceleration [m/s^2] on its speed profile alone (the leader law
    without the slots' gap laws): leader.traffic_aware = false."""
    return _leader_law(v_vc, v_set, v_set_dot, _NO_ACCELS, _NO_USE, accel_max, decel_emergency,
                       decel_follow, decel_comfort)


_NO_ACCELS = np.zeros(0)
_NO_USE = np.zeros(0, dtype=np.bool_)


def member_speed_cap(gap, v_lead, time_gap, min_gap, v):
    """Largest speed reference [m/s] for a member at speed ``v`` [m/s] with a vehicle ``gap``
    [m] ahead.

    The member may close in on the vehicle until the gap is min_gap + time_gap v_lead, with
    the gap error removed over ``time_gap``; inf where nobody is ahead. A vehicle whose speed
    comfortable braking matches in time (at least as fast as the member, or a little slower:
    :func:`_cap_floor`) never caps below min(v, v_lead): a close cut-in by a faster car would
    otherwise ask a near stop (cap ~0 for a zero gap), which the jerk-limited planner turns
    into braking at the friction limit, and one 33 m ahead at 0.2 m/s less than the member
    asks 4.3 m/s^2 (an emergency brake); its acceleration cap (:func:`time_gap_accel`) opens
    the gap comfortably instead.
    """
    gap, v_lead, v = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (gap, v_lead, v)))
    out = np.empty(gap.shape)
    _speed_caps(gap.ravel(), v_lead.ravel(), float(time_gap), float(min_gap), v.ravel(), out.reshape(-1))
    return out


@kernel(error_model="python")
def _speed_cap(gap, v_lead, time_gap, min_gap, v):
    """:func:`member_speed_cap` for one member."""
    if not np.isfinite(gap):
        return np.inf
    cap = max(v_lead + (gap - min_gap - time_gap * v_lead) / time_gap, 0.0)
    return _cap_floor(cap, gap, v, v_lead, min_gap)


@kernel(error_model="python")
def _cap_floor(cap, gap, v, v_lead, min_gap):
    """A speed cap [m/s] never below min(v, v_lead) when matching the leader's speed needs at
    most B_COMFORT of braking (:func:`_closing_bound`): such a vehicle, faster or a little
    slower, asks no more than comfortable braking of the acceleration cap, and the speed cap
    must not ask more (folded into the request as (cap - v) / tau_speed_cap it would)."""
    if _need(gap, v, v_lead, min_gap) <= B_COMFORT:
        return max(cap, min(v, v_lead))
    return cap


@kernel(error_model="python")
def _speed_caps(gap, v_lead, time_gap, min_gap, v, out):
    for i in range(gap.shape[0]):
        out[i] = _speed_cap(gap[i], v_lead[i], time_gap, min_gap, v[i])


@kernel(error_model="python")
def member_caps(gap, v_lead, v, time_gap, min_gap, decel_emergency):
    """Caps of one member at speed ``v`` [m/s] with a vehicle ``gap`` [m] ahead at
    ``v_lead`` [m/s]: (speed cap [m/s] (:func:`member_speed_cap`), acceleration cap [m/s^2]
    (its own gap law, :func:`time_gap_accel`, not below -decel_emergency)); inf, inf where
    nobody is ahead."""
    return (_speed_cap(gap, v_lead, time_gap, min_gap, v),
            max(_gap_law(gap, v, v_lead, time_gap, min_gap), -decel_emergency))


@kernel(error_model="python")
def mate_caps(gap, v_lead, v, spacing, time_gap, min_gap, decel_emergency):
    """Caps of a member at speed ``v`` [m/s] behind a released member still inside the
    formation, ``gap`` [m] ahead at ``v_lead`` [m/s]: a formation-mate, kept at the
    formation's ``spacing`` [m] (the bumper gap of their slots), not at the traffic's
    min_gap + time_gap v (a released member 15 m ahead in a 20 m column is no
    emergency). Speed cap v_lead + (gap - spacing) / time_gap (the gap error removed over
    ``time_gap``; :func:`_cap_floor` as for traffic), acceleration cap
    K_GAP (gap - spacing) + K_REL (v_lead - v) with the bounds of :func:`time_gap_accel`, not
    below -decel_emergency."""
    cap = _cap_floor(max(v_lead + (gap - spacing) / time_gap, 0.0), gap, v, v_lead, min_gap)
    law = _closing_bound(K_GAP * (gap - spacing) + K_REL * (v_lead - v), gap, v, v_lead, min_gap)
    return cap, max(law, -decel_emergency)


@kernel(error_model="python")
def governor_step(m_s_front, m_d, slot_s_front, slot_d, half_w, v_m, active, v_vc, v_set,
                  v_set_dot, others, lim):
    """One step of the governor over all members (compiled; the laws are the functions above).

    Members at their front bumpers (``m_s_front`` [m], ``m_d`` [m]) and their slots
    (``slot_s_front``, ``slot_d``), half widths [m], speeds ``v_m`` [m/s], ``active`` mask;
    the other vehicles ``others`` (control/reference_records.py NeighbourRows: rear, d,
    half_w, v as in :func:`vehicles_ahead`); ``lim`` the packed limits
    (control/reference_road.py GovernorLimits.packed, slots :data:`TIME_GAP` ..). Returns the
    virtual car's acceleration [m/s^2] (:func:`leader_accel` over the slots'
    :func:`time_gap_accel` at the virtual car's speed ``v_vc``; braking that is not an
    emergency, i.e. not below ``-decel_comfort``, at most ``decel_follow`` [m/s^2]), each
    member's gap [m], leader index (-1: none), speed cap [m/s] and acceleration cap [m/s^2]
    (:func:`member_caps`). Vehicles flagged ``others.in_formation`` (a mask as long as the
    others, or empty: none) are not seen by the slots' laws (a released member inside the
    formation: the virtual car braking for it would brake the members ahead of it, which it
    follows), only by the members' caps; ``others.mate_rear`` [m] (as long as the others, or
    empty: none; NaN: not one) is the rear of the slot such a vehicle held, and a member right
    behind it takes :func:`mate_caps` with the spacing of their slots (at least min_gap)
    instead of :func:`member_caps`."""
    o_s_rear, o_d, o_half_w, o_v = others.rear, others.d, others.half_w, others.v
    o_in_formation, o_mate_rear = others.in_formation, others.mate_rear
    time_gap, min_gap, accel_max = lim[TIME_GAP], lim[MIN_GAP], lim[ACCEL_MAX]
    decel_emergency, decel_follow, decel_comfort = (lim[DECEL_EMERGENCY], lim[DECEL_FOLLOW],
                                                    lim[DECEL_MAX])
    n = m_s_front.shape[0]
    gap, v_lead, index = _vehicles_ahead(m_s_front, m_d, half_w, o_s_rear, o_d, o_half_w, o_v)
    slot_rear = o_s_rear
    if o_in_formation.shape[0] == o_s_rear.shape[0]:
        slot_rear = o_s_rear.copy()
        for j in range(o_s_rear.shape[0]):
            if o_in_formation[j]:
                slot_rear[j] = np.inf
    gap_slot, v_lead_slot, _ = _vehicles_ahead(slot_s_front, slot_d, half_w, slot_rear, o_d, o_half_w, o_v)
    acc_slot = np.empty(n)
    v_cap = np.empty(n)
    a_cap = np.empty(n)
    for i in range(n):
        acc_slot[i] = _gap_law(gap_slot[i], v_vc, v_lead_slot[i], time_gap, min_gap)
        j = index[i]
        if j >= 0 and o_mate_rear.shape[0] == o_s_rear.shape[0] and np.isfinite(o_mate_rear[j]):
            spacing = max(o_mate_rear[j] - slot_s_front[i], min_gap)
            v_cap[i], a_cap[i] = mate_caps(gap[i], v_lead[i], v_m[i], spacing, time_gap, min_gap,
                                           decel_emergency)
        else:
            v_cap[i], a_cap[i] = member_caps(gap[i], v_lead[i], v_m[i], time_gap, min_gap, decel_emergency)
    a_vc = _leader_law(v_vc, v_set, v_set_dot, acc_slot, active, accel_max, decel_emergency,
                       decel_follow, decel_comfort)
    return a_vc, gap, index, v_cap, a_cap


@kernel(error_model="python")
def column_caps(slot_s, slot_d, half_w, active, v_cap, a_cap):
    """Members in one column brake as one: each takes the tightest speed and acceleration
    caps of the active members ahead of it whose slots overlap it sideways.

    The caps of :func:`governor_step` come from each member's own gap to the vehicle ahead of
    it, and other members are not among those vehicles. Without this, a cut-in in front of a
    column caps its first member only: it falls behind its slot while the member behind keeps
    its own, and at small gaps the two collide.

    Parameters
    ----------
    slot_s, slot_d : ndarray, shape (n,)
        Slots along and across the road [m].
    half_w : ndarray, shape (n,)
        Members' half widths [m].
    active : ndarray of bool, shape (n,)
        Members still on the road.
    v_cap, a_cap : ndarray, shape (n,)
        Speed caps [m/s] and acceleration caps [m/s^2] (inf: none).

    Returns
    -------
    v_cap, a_cap : ndarray, shape (n,)
        New arrays, never above the given ones.
    """
    n = slot_s.shape[0]
    v_out = v_cap.copy()
    a_out = a_cap.copy()
    for i in range(n):
        for j in range(n):
            if active[j] and slot_s[j] > slot_s[i] and \
                    abs(slot_d[j] - slot_d[i]) < half_w[j] + half_w[i]:
                v_out[i] = min(v_out[i], v_cap[j])
                a_out[i] = min(a_out[i], a_cap[j])
    return v_out, a_out
