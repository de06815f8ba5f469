"""CACC after PATH (Rajamani, Vehicle Dynamics and Control, 2nd ed., eq 7.39; Plexe's
``_cacc``; docs/platoon_laws.md): constant spacing with the leader's and the predecessor's
speed and acceleration over the radio,

    a_r = a1 a_p + a2 a_0 + a3 (v - v_p) + a4 (v - v_0) + a5 (gap - d),
    a1 = 1 - C1, a2 = C1, a3 = -(2 xi - C1 (xi + sqrt(xi^2 - 1))) w_n,
    a4 = -C1 (xi + sqrt(xi^2 - 1)) w_n, a5 = -w_n^2 (on eps = d - gap, i.e. +w_n^2 on gap - d)

with d the spacing [m], C1 [-] the leader weight, xi [-] the damping ratio, w_n = 2 pi f_n
[rad/s] the bandwidth (f_n [Hz]). The predecessor's acceleration a_p is its last desired
acceleration (over the radio, one control period old); the leader's speed v_0 and acceleration
a_0 are the platoon reference's as the member received it (its virtual car: the [comm] copy).
Defaults are Plexe's reference set: d = 5 m, C1 = 0.5, xi = 1, f_n = 0.2 Hz
(control/laws/cacc_path_spec.py).
"""
from __future__ import annotations

import numpy as np

from ...core.kernels import kernel, maximum
from ...models.state import motion_at
from . import platoon
from .cacc_path_spec import DEFAULTS, SPEC  # noqa: F401 (the law's schema and defaults)

PARAMS = (*platoon.COMMON, *platoon.ACC_PARAMS, "spacing_m", "c1", "xi", "omega_n_hz")
SPACING, C1, XI, F_N = range(platoon.OWN_AT, platoon.OWN_AT + 4)
"""The columns of d [m], C1 [-], xi [-] and f_n [Hz]."""


@kernel
def accel_at(gap, v, vp, ap, v0, a0, d, c1, xi, wn):
    """The PATH law's a_r [m/s^2] (wn [rad/s]; xi >= 1)."""
    q = xi + np.sqrt(maximum(xi * xi - 1.0, 0.0))
    a3 = -(2.0 * xi - c1 * q) * wn
    a4 = -c1 * q * wn
    a5 = -wn * wn
    return (1.0 - c1) * ap + c1 * a0 + a3 * (v - vp) + a4 * (v - v0) + a5 * (d - gap)


@kernel(inline="always")
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    """Member i's model input (control/laws/__init__.py): the PATH law behind its
    predecessor, the virtual-structure law at the head."""
    p = fleet.pred[i]
    if p < 0:
        return platoon.head_input(fleet, state, i, target, v_cap_i, a_cap_i)
    kind, x, L, u_last = fleet.kind, state.x, fleet.L, state.u_last
    v, _, _ = motion_at(kind, x, i, state.speed_in[i])
    v0, a0 = platoon.leader_at(target)
    a = accel_at(platoon.gap_at(x, i, p, L), v, platoon.speed_of(kind, x, p, u_last),
                 platoon.accel_of(kind, p, u_last), v0, a0, L[i, SPACING], L[i, C1], L[i, XI],
                 2.0 * np.pi * L[i, F_N])
    return platoon.member_input(a, fleet, state, i, target, v_cap_i, a_cap_i)


def pack(cfg):
    """(n, len(PARAMS)) rows from a sim/fleet.py FleetConfig (controller.cacc_path)."""
    return platoon.pack_rows(cfg, "cacc_path", PARAMS[platoon.OWN_AT:], DEFAULTS)
