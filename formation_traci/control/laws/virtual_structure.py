"""The seed's law (its default): the virtual-structure formation controller, eqs (2.5)-(2.10),
feeding the gain-scheduled speed loop (3.32-3.34) and steering-rate loop (3.37) of the dynamic
model, or the unicycle's inputs directly (eq 2.2).

Law parameters (columns of the per-member array ``L``, :data:`PARAMS`): the position gain k of
(2.7) [m/s] and the heading gain k_theta of (2.8) [1/s].
"""
from __future__ import annotations

import numpy as np

from ...core.kernels import kernel, minimum
from ...models.bicycle import S
from ...models.state import KINEMATIC, motion_at
from ..formation import formation_at
from ..schedule import speed_law, yaw_law

PARAMS = ("k", "k_theta")
"""Columns of the law's parameter rows."""
K, K_THETA = 0, 1
"""The columns of k [m/s] and k_theta [1/s]."""


@kernel(inline="always")
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    """Model input of member i for its desired point ``target`` (p, p', p''): (u0, u1, capped
    v_ref [m/s], omega_ref [rad/s], theta* dot [rad/s], v_ref dot [m/s^2], ex, ey [m], heading
    error [rad]). u0, u1: a_r [m/s^2] and the steering rate [rad/s] (dynamic model), v_ref
    and omega_ref (unicycle). The member ahead (``fleet.pred``) is not used by this law."""
    kind, x, L = fleet.kind, state.x, fleet.L
    v, r, course = motion_at(kind, x, i, state.speed_in[i])
    vr, om, tsd, vrd, ex, ey, he = formation_at(
        target, x[i, S.X], x[i, S.Y], v * np.cos(course), v * np.sin(course), x[i, S.PSI],
        state.theta_star[i], L[i, K], L[i, K_THETA])
    vr = minimum(vr, v_cap_i)
    if kind == KINEMATIC:
        return vr, om, vr, om, tsd, vrd, ex, ey, he
    a_r = minimum(speed_law(fleet.gains, i, vr, v), a_cap_i)
    return a_r, yaw_law(fleet.gains, i, om, r), vr, om, tsd, vrd, ex, ey, he


def pack(cfg) -> np.ndarray:
    """(n, 2) rows (k, k_theta) of a sim/fleet.py FleetConfig."""
    n = cfg.n
    return np.column_stack([np.broadcast_to(np.asarray(cfg.k, dtype=float), (n,)),
                            np.broadcast_to(np.asarray(cfg.k_theta, dtype=float), (n,))])
