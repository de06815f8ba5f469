"""Jerk-limited slot transitions: the minimum-jerk (quintic) law and its comfort duration.

A slot moves from offset A to offset B (road frame: along, across [m]) over a duration T
along the minimum-jerk profile (Flash & Hogan 1985): with tau = (t - t0) / T in [0, 1],

    h(tau)    = 10 tau^3 - 15 tau^4 + 6 tau^5,        offset(t) = A + h(tau) (B - A),
    h'(tau)   = 30 tau^2 (1 - tau)^2,                 peak 15/8 at tau = 1/2,
    h''(tau)  = 60 tau (1 - tau) (1 - 2 tau),         peak 10/sqrt(3) at tau = (3 -+ sqrt 3)/6,
    h'''(tau) = 60 (1 - 6 tau + 6 tau^2),             peak 60 at tau = 0 and 1.

Offset, rate and acceleration are continuous (zero rate and acceleration at both ends), so
the controller gets exact slot derivatives instead of a jump. For a displacement D the
peaks are a = (10/sqrt 3) D / T^2 and j = 60 D / T^3, so the shortest duration that keeps
them within a_max and j_max is

    T = max(T_min, sqrt(10/sqrt(3) |D| / a_max), (60 |D| / j_max)^(1/3)),

taken over both axes (across: lateral limits, along: longitudinal limits).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.kernels import kernel

H1_PEAK = 15.0 / 8.0
"""Peak of h' [-]."""
H2_PEAK = 10.0 / math.sqrt(3.0)
"""Peak of |h''| [-]."""
H3_PEAK = 60.0
"""Peak of |h'''| [-]."""


@dataclass(frozen=True, slots=True)
class ComfortLimits:
    """Bounds a slot transition keeps on its own (the road's curvature adds v^2 kappa)."""

    lat_accel: float  # lateral acceleration of the slot [m/s^2]
    lat_jerk: float  # lateral jerk of the slot [m/s^3]
    lon_accel: float  # longitudinal acceleration of the slot relative to the virtual car [m/s^2]
    lon_jerk: float  # longitudinal jerk relative to the virtual car [m/s^3]
    min_duration: float  # shortest transition [s]


def transition_duration(d_along, d_across, lim: ComfortLimits) -> float:
    """Shortest duration [s] of a quintic transition that keeps every slot within ``lim``.

    Parameters
    ----------
    d_along, d_across : float or ndarray
        Displacements of the slots along and across the road [m]; the largest counts.
    lim : ComfortLimits
    """
    dl = float(np.max(np.abs(d_along), initial=0.0))
    dc = float(np.max(np.abs(d_across), initial=0.0))
    return max(lim.min_duration,
               math.sqrt(H2_PEAK * dc / lim.lat_accel), (H3_PEAK * dc / lim.lat_jerk) ** (1 / 3),
               math.sqrt(H2_PEAK * dl / lim.lon_accel), (H3_PEAK * dl / lim.lon_jerk) ** (1 / 3))


@kernel
def quintic(t, t0, T):
    """h, h_dot [1/s], h_ddot [1/s^2] of the minimum-jerk profile at time t [s] of a
    transition starting at t0 [s] lasting T [s] (0 before, 1 after)."""
    if T <= 0.0 or t >= t0 + T:
        return 1.0 if t >= t0 else 0.0, 0.0, 0.0
    if t <= t0:
        return 0.0, 0.0, 0.0
    tau = (t - t0) / T
    h = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    h1 = 30.0 * tau * tau * (1.0 - tau) * (1.0 - tau) / T
    h2 = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / (T * T)
    return h, h1, h2


@kernel
def rate_basis(t, t0, T):
    """g T [s], g_dot [-], g_ddot [1/s] of the quintic that starts with unit rate and ends at
    rest: g(tau) = tau - 6 tau^3 + 8 tau^4 - 3 tau^5 (g = g'' = 0 at both ends, g'(0) = 1,
    g'(1) = 0), so that a slot starting with rate r0 [m/s] adds r0 T g(tau) to its offset
    (zero before t0 and from t0 + T on; at t0 the rate is r0)."""
    if T <= 0.0 or t < t0 or t >= t0 + T:
        return 0.0, 0.0, 0.0
    tau = (t - t0) / T
    t2 = tau * tau
    g = tau + t2 * tau * (-6.0 + tau * (8.0 - 3.0 * tau))
    g1 = 1.0 + t2 * (-18.0 + tau * (32.0 - 15.0 * tau))
    g2 = tau * (-36.0 + tau * (96.0 - 60.0 * tau)) / T
    return g * T, g1, g2


@kernel
def slot_at(plan_row, t):
    """Slot of one member at time t [s] from its plan row (PLAN_* columns):
    (dx, dy, dx_dot, dy_dot, dx_ddot, dy_ddot) [m, m/s, m/s^2]. The start rates (a joining
    vehicle's own motion relative to the formation) add r0 T g(tau) (:func:`rate_basis`)."""
    h, h1, h2 = quintic(t, plan_row[4], plan_row[5])
    ex = plan_row[2] - plan_row[0]
    ey = plan_row[3] - plan_row[1]
    rx = plan_row[6]
    ry = plan_row[7]
    g, g1, g2 = rate_basis(t, plan_row[4], plan_row[5])
    return (plan_row[0] + h * ex + rx * g, plan_row[1] + h * ey + ry * g,
            h1 * ex + rx * g1, h1 * ey + ry * g1, h2 * ex + rx * g2, h2 * ey + ry * g2)


(PLAN_FROM_ALONG, PLAN_FROM_ACROSS, PLAN_TO_ALONG, PLAN_TO_ACROSS, PLAN_T0, PLAN_T,
 PLAN_RATE_ALONG, PLAN_RATE_ACROSS) = range(8)
N_PLAN = 8
"""A slot plan is an (n, 8) float array, one row per member: the transition from
(from_along, from_across) to (to_along, to_across) [m] starting at t0 [s] lasting T [s],
with start rates (rate_along, rate_across) [m/s] (zero except for a joining vehicle). A
member at rest in its slot has from == to and zero rates (any t0, T)."""


def hold_plan(slots: np.ndarray) -> np.ndarray:
    """A plan that keeps every member in its (n, 2) slot."""
    slots = np.asarray(slots, dtype=float)
    plan = np.zeros((len(slots), N_PLAN))
    plan[:, 0:2] = slots
    plan[:, 2:4] = slots
    return plan


@kernel
def plan_slots_into(plan, t, dt, out):
    """Fill out (n_ctrl, n, 6) (control/reference.py SLOT_FIELDS) with every member's slot
    and its rates at the start of each control period t + j dt [s] of a step."""
    for j in range(out.shape[0]):
        tj = t + j * dt
        for i in range(plan.shape[0]):
            (out[j, i, 0], out[j, i, 1], out[j, i, 2], out[j, i, 3], out[j, i, 4],
             out[j, i, 5]) = slot_at(plan[i], tj)
    return out


def slots_at(plan: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Offsets (n, 2) [m], rates (n, 2) [m/s] and accelerations (n, 2) [m/s^2] at time t."""
    out = np.array([slot_at(row, float(t)) for row in np.asarray(plan, dtype=float)]).reshape(-1, 6)
    return out[:, 0:2], out[:, 2:4], out[:, 4:6]


def warm_kernels() -> None:
    """Compile (or load) this module's kernels for the argument types a maneuver run passes,
    on empty inputs (sim/warm.py: one compilation covers every scenario kind)."""
    row = np.zeros(N_PLAN)
    row[PLAN_T] = 1.0
    quintic(0.0, 0.0, 1.0)
    rate_basis(0.0, 0.0, 1.0)
    slot_at(row, 0.0)
    plan_slots_into(row.reshape(1, N_PLAN), 0.0, 0.01, np.empty((1, 1, 6)))
