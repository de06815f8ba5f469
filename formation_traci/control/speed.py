"""Linear velocity controller, eqs (3.32)-(3.34)."""
from __future__ import annotations

from .schedule import GainSchedule, apply


def desired_acceleration(v_ref, v, sched: GainSchedule):
    """a_r = K(e) e with e = v_ref - v, eqs (3.32)-(3.33) [m/s^2]; speeds in m/s
    (schedule.p_law, the kernel the step uses)."""
    return apply(v_ref, v, sched)
