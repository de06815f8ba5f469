"""Room for a member to move sideways: time-gap margins to the vehicles in its target lane.

A member that moves from lateral offset d0 to d1 (road frame, left positive [m]) during a
transition of duration T [s] needs, towards every vehicle whose body overlaps its target
band [d1 - w/2 - LATERAL_MARGIN, d1 + w/2 + LATERAL_MARGIN] and that is not on its present
band (the vehicle ahead in its own lane is the governor's business):

* ahead (vehicle's centre ahead of the member's): rear bumper minus the member's front bumper
  at the foremost point of its path >= g_min + t_gap v_member + max(0, v_member - v_other) T;
* behind: the member's rear bumper at the rearmost point of its path minus the other's front
  bumper >= g_min + t_gap v_other + max(0, v_other - v_member) T.

The closing terms keep the margin for the whole transition at constant speeds; the time gap
is the follower's (the member ahead, the other car behind), as in a constant-time-gap law.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LATERAL_MARGIN = 0.3
"""Bodies closer sideways than this count as sharing the target band [m]."""


@dataclass(frozen=True, slots=True)
class Others:
    """Vehicles around the formation in road coordinates (arrays of shape (k,))."""

    ids: tuple[str, ...]
    s: np.ndarray  # centre arc length [m]
    d: np.ndarray  # centre lateral offset, left positive [m]
    length: np.ndarray  # [m]
    width: np.ndarray  # [m]
    v: np.ndarray  # [m/s]


@dataclass(frozen=True, slots=True)
class GapVerdict:
    ok: bool
    reason: str  # empty when ok
    shortfall: float  # largest missing gap [m] (0 when ok)


def check_gaps(s_path, d0, d1, length, width, v_m, others: Others, duration: float,
               time_gap: float, min_gap: float, member_ids=None) -> GapVerdict:
    """Check every member's target band against ``others``.

    Parameters
    ----------
    s_path : ndarray, shape (n, 2)
        Rearmost and foremost centre arc length of each member over its transition [m].
    d0, d1 : ndarray, shape (n,)
        Lateral offset now and at the end of the transition [m].
    length, width, v_m : ndarray, shape (n,)
        Body length [m], width [m] and speed [m/s] of each member.
    duration : float
        Transition duration T [s].
    time_gap, min_gap : float
        Margins t_gap [s] and g_min [m].
    """
    s_path = np.asarray(s_path, dtype=float).reshape(-1, 2)
    n = len(s_path)
    ids = member_ids or [str(i) for i in range(n)]
    worst, why = 0.0, ""
    for i in range(n):
        if abs(d1[i] - d0[i]) < 1e-9 or len(others.ids) == 0:
            continue
        half = width[i] / 2 + LATERAL_MARGIN
        o_half = others.width / 2
        in_target = np.abs(others.d - d1[i]) < half + o_half
        in_own = np.abs(others.d - d0[i]) < width[i] / 2 + o_half
        for j in np.flatnonzero(in_target & ~in_own):
            ahead = (others.s[j] - others.length[j] / 2) - (s_path[i, 1] + length[i] / 2)
            behind = (s_path[i, 0] - length[i] / 2) - (others.s[j] + others.length[j] / 2)
            if ahead >= 0.0:
                gap, where = ahead, "ahead of"
                need = min_gap + time_gap * v_m[i] + max(0.0, v_m[i] - others.v[j]) * duration
            elif behind >= 0.0:
                gap, where = behind, "behind"
                need = min_gap + time_gap * others.v[j] + max(0.0, others.v[j] - v_m[i]) * duration
            else:  # the bodies overlap along the road: side by side with the path
                gap, need, where = -np.inf, 0.0, "beside"
            if need - gap > worst:
                worst = need - gap
                if where == "beside":
                    why = f"{others.ids[j]} is beside member {ids[i]!r} in its target lane"
                else:
                    why = (f"{others.ids[j]} {gap:.1f} m {where} member {ids[i]!r} in its target lane "
                           f"(needs {need:.1f} m)")
    return GapVerdict(bool(worst <= 0.0), why, float(worst) if np.isfinite(worst) else np.inf)
