"""Opening a gap for ramp traffic: which ramp vehicles a formation yields to, and how hard.

A ramp vehicle on an on-ramp (road/ramps.py: the ramp's feeder lanes and the acceleration
lane) is mapped onto the merge lane at the same distance from the join: at a distance ``dist``
[m] before the join's start (negative once it is on the acceleration lane) its front bumper is
at ``s_r = s_start - dist`` on the reference line. It merges at ``s_m = s_start + merge_at *
length`` (``merge_at`` of the acceleration lane, 0 for a direct join), reached at its own speed
after ``T = (s_m - s_r) / v_r``; past ``s_m`` and still on the acceleration lane it merges by the
lane's end, ``T = (s_start + length - s_r) / v_r`` (at least ``min_time_s``). A ramp vehicle is
the law's until it has left the ramp's lanes (the caller's: then it is traffic like any other).

Of the members in the merge lane, the front-most bumper is at ``s_F`` (speed ``v_F``) and the
rear-most rear bumper at ``s_R``. The ramp vehicle of length ``L_r`` and time gap ``tau_r`` is

* **clear behind** when its front trails ``s_R`` by at least ``g_R = min_gap + tau_r v_r`` (its
  own safe time gap): nothing to do;
* **clear ahead** when its rear leads ``s_F`` by at least ``g_F = min_gap + max(tau_r, tau_F) v_F``
  (``tau_F``: the formation's own time gap, ``follow_gap_s``, so that once it has merged the
  formation follows it at its usual gap, not at the ramp driver's shorter one, from which a
  brake of the merged vehicle is an emergency for the member behind it): the front member
  follows it as it follows a leader in its lane (the governor's time-gap law,
  ``K_GAP (lead - g_F) + K_REL (v_r - v_F)``, not below ``-a_comfort``), so the gap stays open
  until it has merged; a yield to it goes on;
* otherwise **in conflict**. The formation opens the gap ahead of its front member when a
  constant deceleration ``a`` of the formation over ``T`` gives it (constant ramp speed):

      (s_r - L_r - s_F) + (v_r - v_F) T + a T^2 / 2 >= g_F
      a_req = 2 (g_F - (s_r - L_r - s_F) - (v_r - v_F) T) / T^2

  and ``a_req <= a_comfort``: it *yields*, its acceleration capped at ``-a_req`` (when the
  formation's own gap ``g_F`` would need more, ``a_req`` is that of the ramp driver's own gap,
  ``min_gap + tau_r v_F``: the formation never yields less than to that gap; recomputed
  every step, so the cap relaxes as the gap opens). A conflict that needs more than
  ``a_comfort`` is left to the ramp vehicle (it merges behind), unless the formation already
  yields to it and it needs at most twice that: then the cap stays, at most ``a_comfort`` (no
  switching back and forth at the threshold; a ramp vehicle that slows down beside the
  formation is let go).

A ramp vehicle on the acceleration lane that is slower than the formation and ahead of its front
member (a queue at the lane's end in stop-and-go) may merge into the first gap, long before its
own ``T``: its ``T`` is then the time the formation's front takes to reach its rear, ``lead / (v_F
- v_r)`` with ``lead = s_r - L_r - s_F``, when that is shorter: a vehicle standing at the lane's
end is otherwise never within the horizon, and may push into the merge lane a few metres ahead of
a member.

Only ramp vehicles within ``horizon_s`` of the merge (``T <= horizon_s``) are considered. Pure functions of (state, input, params), compiled.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..core.kernels import kernel
from .governor import K_GAP, K_REL

OUTSIDE = -1
"""A ramp vehicle beyond the horizon or past the merge point."""
CLEAR = 0
"""A ramp vehicle within the horizon, clear of the formation."""
YIELD = 1
"""A ramp vehicle the formation opens a gap for."""
BEHIND = 2
"""A ramp vehicle in conflict the formation cannot yield to within comfort: it merges behind."""


class MergeParams(NamedTuple):
    """The yield law's parameters."""

    horizon_s: float  # how far ahead in time ramp vehicles are considered [s]
    a_comfort_mps2: float  # the largest deceleration the formation yields with [m/s^2]
    min_gap_m: float  # standstill gap added to the ramp vehicle's time gap [m]
    merge_at: float  # where along the acceleration lane ramp vehicles merge [-], 0..1
    min_time_s: float = 1.0  # the shortest time to the merge the deceleration is spread over [s]
    follow_gap_s: float = 0.0  # the formation's own time gap behind a vehicle ahead [s]


def merge_params(spec, follow_gap_s: float = 0.0) -> MergeParams:
    """The law's parameters from the scenario's ``[cooperation]`` (scenario/cooperation.py) and
    the formation's time gap [s] (``[leader] time_gap``)."""
    return MergeParams(float(spec.horizon_s), float(spec.decel_mps2), float(spec.min_gap_m),
                       float(spec.merge_at), follow_gap_s=float(follow_gap_s))


class MergeSite(NamedTuple):
    """One join of ramp traffic on the reference line (road/ramps.py RampJoin)."""

    s_start: float  # where the join starts [m]
    length: float  # the acceleration lane's length (0: a direct join) [m]


class RampTraffic(NamedTuple):
    """The ramp vehicles of one join, one entry each."""

    dist: np.ndarray  # distance of the front bumper before the join's start [m] (< 0: past it)
    v: np.ndarray  # speed [m/s]
    length: np.ndarray  # length [m]
    tau: np.ndarray  # time gap of its driver [s]
    yielding: np.ndarray  # bool: the formation yields to it already


class MergeLane(NamedTuple):
    """The formation's members in the merge lane at the join."""

    s_front: float  # front-most front bumper [m]
    v_front: float  # that member's speed [m/s]
    s_rear: float  # rear-most rear bumper [m]


@kernel
def yield_to_ramp(site, ramp, lane, p, decision):
    """Decide for every ramp vehicle (``decision`` (m,) int64 out: OUTSIDE, CLEAR, YIELD, BEHIND;
    the module docstring) and return the formation's acceleration cap [m/s^2] (``inf``: none)."""
    cap = np.inf
    s_m = site.s_start + p.merge_at * site.length
    for j in range(ramp.dist.shape[0]):
        decision[j] = OUTSIDE
        v_r = max(ramp.v[j], 0.1)
        s_r = site.s_start - ramp.dist[j]
        s_to = s_m if s_r < s_m else site.s_start + site.length  # past s_m: by the lane's end
        t = max((s_to - s_r) / v_r, p.min_time_s)
        lead = s_r - ramp.length[j] - lane.s_front
        if t > p.horizon_s and s_r > site.s_start and lead > 0.0 and lane.v_front > v_r:
            t = max(lead / (lane.v_front - v_r), p.min_time_s)  # slow on the lane: reached first
        if t > p.horizon_s:
            continue
        decision[j] = CLEAR
        g_front = p.min_gap_m + max(ramp.tau[j], p.follow_gap_s) * lane.v_front
        g_rear = p.min_gap_m + ramp.tau[j] * ramp.v[j]
        if s_r <= lane.s_rear - g_rear:
            continue
        if lead >= g_front:  # clear ahead: followed like a leader in the merge lane (a yield goes on)
            follow = K_GAP * (lead - g_front) + K_REL * (ramp.v[j] - lane.v_front)
            cap = min(cap, max(follow, -p.a_comfort_mps2))
            if ramp.yielding[j]:
                decision[j] = YIELD
            continue
        limit = 2.0 * p.a_comfort_mps2 if ramp.yielding[j] else p.a_comfort_mps2
        a_req = 2.0 * (g_front - lead - (ramp.v[j] - lane.v_front) * t) / (t * t)
        if a_req > limit:  # the formation's gap costs too much: at least the driver's own
            g_own = p.min_gap_m + ramp.tau[j] * lane.v_front
            a_req = 2.0 * (g_own - lead - (ramp.v[j] - lane.v_front) * t) / (t * t)
        if a_req <= limit:
            decision[j] = YIELD
            cap = min(cap, -min(max(a_req, 0.0), p.a_comfort_mps2))
        else:
            decision[j] = BEHIND
    return cap
