"""Angular velocity controller, eqs (3.35)-(3.38)."""
from __future__ import annotations

from .schedule import GainSchedule, gain


def steering_angle(omega_ref, yaw_rate, sched: GainSchedule):
    """Direct steering law delta = K(e) e, e = omega_ref - psi dot, eqs (3.35)-(3.36) [rad].

    Kept for comparison: the seed replaces it by the rate law because it spikes the front
    slip angle when the reference jumps (Figure 3.38).
    """
    e = omega_ref - yaw_rate
    return gain(e, sched) * e


def steering_rate(omega_ref, yaw_rate, sched: GainSchedule):
    """Steering-rate law delta dot = K(e) e, eq (3.37) [rad/s]; delta is integrated (3.38)."""
    e = omega_ref - yaw_rate
    return gain(e, sched) * e
