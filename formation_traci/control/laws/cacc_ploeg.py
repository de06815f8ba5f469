"""Ploeg's CACC (Ploeg et al., "Design and experimental evaluation of cooperative adaptive
cruise control", ITSC 2011; Plexe's ``_ploeg``; docs/platoon_laws.md): constant time gap with
the predecessor's desired acceleration over the radio, a dynamic controller

    u' = (1 / h) [ -u + kp (gap - r0 - h v) + kd (v_p - v - h a) + u_p ],   a_r = u,

integrated (explicit Euler, as Plexe) over the control period dt_c [s]. u is the member's own
last a_r (``u_last[i]``), a its acceleration (taken as u: the lag-free model realises a_r), u_p
the predecessor's last a_r (over the radio, one control period old). Defaults are Plexe's:
h = 0.5 s, kp = 0.2 1/s^2, kd = 0.7 1/s, r0 = 2 m (control/laws/cacc_ploeg_spec.py).
"""
from __future__ import annotations

from ...core.kernels import kernel
from ...models.state import motion_at
from . import platoon
from .cacc_ploeg_spec import DEFAULTS, SPEC  # noqa: F401 (the law's schema and defaults)

PARAMS = (*platoon.COMMON, *platoon.ACC_PARAMS, "h_s", "kp", "kd", "standstill_m")
H_S, KP, KD, R0 = range(platoon.OWN_AT, platoon.OWN_AT + 4)
"""The columns of h [s], kp [1/s^2], kd [1/s] and r0 [m]."""


@kernel
def accel_at(u, gap, v, vp, up, h, kp, kd, r0, dt_c):
    """Ploeg's u after one control period of dt_c [s] [m/s^2]."""
    du = (1.0 / h) * (-u + kp * (gap - r0 - h * v) + kd * (vp - v - h * u) + up)
    return u + du * dt_c


@kernel(inline="always")
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    """Member i's model input (control/laws/__init__.py): Ploeg's law behind its
    predecessor, the virtual-structure law at the head."""
    p = fleet.pred[i]
    if p < 0:
        return platoon.head_input(fleet, state, i, target, v_cap_i, a_cap_i)
    kind, x, L, u_last = fleet.kind, state.x, fleet.L, state.u_last
    v, _, _ = motion_at(kind, x, i, state.speed_in[i])
    u = platoon.accel_of(kind, i, u_last)
    a = accel_at(u, platoon.gap_at(x, i, p, L), v, platoon.speed_of(kind, x, p, u_last),
                 platoon.accel_of(kind, p, u_last), L[i, H_S], L[i, KP], L[i, KD], L[i, R0],
                 fleet.dt_c)
    return platoon.member_input(a, fleet, state, i, target, v_cap_i, a_cap_i)


def pack(cfg):
    """(n, len(PARAMS)) rows from a sim/fleet.py FleetConfig (controller.cacc_ploeg)."""
    return platoon.pack_rows(cfg, "cacc_ploeg", PARAMS[platoon.OWN_AT:], DEFAULTS)
