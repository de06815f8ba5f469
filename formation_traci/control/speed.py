"""Linear velocity controller, eqs (3.32)-(3.34)."""
from __future__ import annotations

from .schedule import GainSchedule, gain


def desired_acceleration(v_ref, v, sched: GainSchedule):
    """a_r = K(e) e with e = v_ref - v, eqs (3.32)-(3.33) [m/s^2]; speeds in m/s."""
    e = v_ref - v
    return gain(e, sched) * e
