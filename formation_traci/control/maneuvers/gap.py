"""Room for members to move: predicted time-gap margins to the vehicles around them.

A member at arc length s0 and lateral offset d0 [m] moves during a transition of duration T
[s] by (D_along, d1 - d0) along the minimum-jerk profile h(tau) of transition.py while the
formation drives on at its speed v. The other vehicles are predicted at constant speed:

    s_m(tau) = s0 + v tau T + h(tau) D_along,      d_m(tau) = d0 + h(tau) (d1 - d0),
    s_o(tau) = s_o + v_o tau T.

Whenever the member's body and another vehicle's body overlap sideways (closer than
LATERAL_MARGIN) at some tau in [0, 1], the bumper-to-bumper gap between them must be at least
g_min + t_gap v_follower: the member's speed when the other is ahead, the other's when it is
behind (ahead, the larger of these margins and the governor's time gap and standstill gap,
so that the member does not land inside the gap its own speed cap keeps). Vehicles the member already shares its lane with at tau = 0 are left out (the
governor keeps the member's gap to the one ahead; the one behind follows it already).
Checked on SAMPLES values of tau.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .transition import quintic

LATERAL_MARGIN = 0.3
"""Bodies closer sideways than this count as sharing a lane [m]."""
SAMPLES = 41
"""Instants of the transition at which the predicted gaps are checked [-]."""


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


class GapMargins(NamedTuple):
    """The margins :func:`check_gaps` asks of a member's path."""

    time_gap: float  # t_gap [s]
    min_gap: float  # g_min [m]
    ahead_time_gap: float | None = None  # towards vehicles ahead of a member (None: time_gap)
    ahead_min_gap: float | None = None  # [m] (None: min_gap)


def check_gaps(s0, along_shift, d0, d1, length, width, v_m, others: Others, duration: float,
               margins: GapMargins, member_ids=None) -> GapVerdict:
    """Check every member's predicted path against ``others``.

    Parameters
    ----------
    s0, along_shift : ndarray, shape (n,)
        Centre arc length now [m] and slot displacement along the road D_along [m].
    d0, d1 : ndarray, shape (n,)
        Lateral offset now and at the end of the transition [m].
    length, width, v_m : ndarray, shape (n,)
        Body length [m], width [m] and speed [m/s] of each member (v_m: also the speed the
        formation drives on at).
    duration : float
        Transition duration T [s].
    margins : GapMargins
        Margins t_gap [s] and g_min [m]; towards vehicles ahead of a member
        ``ahead_time_gap``, ``ahead_min_gap`` (default: the same): pass the governor's time
        gap so that a member never lands inside the gap its own speed cap keeps.
    """
    time_gap, min_gap, ahead_time_gap, ahead_min_gap = margins
    n = len(s0)
    ids = member_ids or [str(i) for i in range(n)]
    if len(others.ids) == 0:
        return GapVerdict(True, "", 0.0)
    a_time = time_gap if ahead_time_gap is None else ahead_time_gap
    a_min = min_gap if ahead_min_gap is None else ahead_min_gap
    tau = np.linspace(0.0, 1.0, SAMPLES)
    h = np.array([quintic(x, 0.0, 1.0)[0] for x in tau])[:, None]  # (S, 1)
    o_half = others.width / 2
    worst, why = 0.0, ""
    for i in range(n):
        if abs(d1[i] - d0[i]) < 1e-9 and abs(along_shift[i]) < 1e-9:
            continue
        fresh = np.abs(others.d - d0[i]) >= width[i] / 2 + o_half  # not in its lane now
        s_m = s0[i] + v_m[i] * tau[:, None] * duration + h * along_shift[i]
        d_m = d0[i] + h * (d1[i] - d0[i])
        s_o = others.s[None, :] + others.v[None, :] * tau[:, None] * duration
        side = (np.abs(d_m - others.d[None, :]) < width[i] / 2 + o_half[None, :] + LATERAL_MARGIN) & fresh
        if not side.any():
            continue
        ahead = s_o >= s_m
        gap = np.where(ahead, (s_o - others.length / 2) - (s_m + length[i] / 2),
                       (s_m - length[i] / 2) - (s_o + others.length / 2))
        need = np.where(ahead, a_min + a_time * v_m[i], min_gap + time_gap * others.v[None, :])
        short = np.where(side, need - gap, -np.inf)
        k, j = np.unravel_index(np.argmax(short), short.shape)
        if short[k, j] > worst:
            worst = float(short[k, j])
            where = "ahead of" if ahead[k, j] else "behind"
            why = (f"{others.ids[j]} would be {gap[k, j]:.1f} m {where} member {ids[i]!r} "
                   f"(needs {need[k, j]:.1f} m) {tau[k] * duration:.1f} s into the maneuver")
    return GapVerdict(bool(worst <= 0.0), why, worst)
