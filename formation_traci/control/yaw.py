"""Angular velocity controller, eqs (3.35)-(3.38)."""
from __future__ import annotations

from .schedule import GainSchedule, apply


def steering_angle(omega_ref, yaw_rate, sched: GainSchedule):
    """Direct steering law delta = K(e) e, e = omega_ref - psi dot, eqs (3.35)-(3.36) [rad].

    Kept for comparison: the seed replaces it by the rate law because it spikes the front
    slip angle when the reference jumps (Figure 3.38).
    """
    return apply(omega_ref, yaw_rate, sched)


def steering_rate(omega_ref, yaw_rate, sched: GainSchedule):
    """Steering-rate law delta dot = K(e) e, e = omega_ref - psi dot, eq (3.37) [rad/s];
    delta is integrated (3.38). schedule.p_law, the kernel the step uses."""
    return apply(omega_ref, yaw_rate, sched)
