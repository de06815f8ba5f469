"""The seed's law (its default): the virtual-structure formation controller, eqs (2.5)-(2.10),
feeding the gain-scheduled speed loop (3.32-3.34) and steering-rate loop (3.37) of the dynamic
model, or the unicycle's inputs directly (eq 2.2).

Law parameters (columns of the per-member array ``L``, :data:`PARAMS`): the position gain k of
(2.7) [m/s] and the heading gain k_theta of (2.8) [1/s].
"""
from __future__ import annotations

import numpy as np

from ...kernels import kernel, minimum
from ...models.bicycle import S
from ...models.state import KINEMATIC, motion_at
from ..formation import formation_at
from ..schedule import p_law

PARAMS = ("k", "k_theta")
"""Columns of the law's parameter rows."""


@kernel
def input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy, tax, tay,
             v_cap_i, a_cap_i, pred_i, u_last, dt_c):
    """Model input of member i for its desired point (p, p', p''): (u0, u1, capped v_ref
    [m/s], omega_ref [rad/s], theta* dot [rad/s], v_ref dot [m/s^2], ex, ey [m], heading
    error [rad]). u0, u1: a_r [m/s^2] and the steering rate [rad/s] (dynamic model), v_ref
    and omega_ref (unicycle). ``pred_i`` (the member ahead) is not used by this law."""
    v, r, course = motion_at(kind, x, i, speed_in_i)
    vr, om, tsd, vrd, ex, ey, he = formation_at(
        px, py, tvx, tvy, tax, tay, x[i, S.X], x[i, S.Y], v * np.cos(course), v * np.sin(course),
        x[i, S.PSI], theta_star_i, L[i, 0], L[i, 1])
    vr = minimum(vr, v_cap_i)
    if kind == KINEMATIC:
        return vr, om, vr, om, tsd, vrd, ex, ey, he
    a_r = minimum(p_law(vr, v, gains[i, 0], gains[i, 1], gains[i, 2]), a_cap_i)
    return (a_r, p_law(om, r, gains[i, 3], gains[i, 4], gains[i, 5]), vr, om, tsd, vrd, ex, ey,
            he)


def pack(cfg) -> np.ndarray:
    """(n, 2) rows (k, k_theta) of a sim/fleet.py FleetConfig."""
    n = cfg.n
    return np.column_stack([np.broadcast_to(np.asarray(cfg.k, dtype=float), (n,)),
                            np.broadcast_to(np.asarray(cfg.k_theta, dtype=float), (n,))])
