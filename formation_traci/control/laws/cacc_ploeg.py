"""Ploeg's CACC (Ploeg et al., "Design and experimental evaluation of cooperative adaptive
cruise control", ITSC 2011; Plexe's ``_ploeg``; docs/platoon_laws.md): constant time gap with
the predecessor's desired acceleration over the radio, a dynamic controller

    u' = (1 / h) [ -u + kp (gap - r0 - h v) + kd (v_p - v - h a) + u_p ],   a_r = u,

integrated (explicit Euler, as Plexe) over the control period dt_c [s]. u is the member's own
last a_r (``u_last[i]``), a its acceleration (taken as u: the lag-free model realises a_r), u_p
the predecessor's last a_r (over the radio, one control period old). Defaults are Plexe's:
h = 0.5 s, kp = 0.2 1/s^2, kd = 0.7 1/s, r0 = 2 m.
"""
from __future__ import annotations

from ...kernels import kernel
from ...models.state import motion_at
from . import platoon

PARAMS = (*platoon.COMMON, *platoon.ACC_PARAMS, "h_s", "kp", "kd", "standstill_m")
DEFAULTS = {"h_s": 0.5, "kp": 0.2, "kd": 0.7, "standstill_m": 2.0}
_H = platoon.OWN_AT


@kernel
def accel_at(u, gap, v, vp, up, h, kp, kd, r0, dt_c):
    """Ploeg's u after one control period of dt_c [s] [m/s^2]."""
    du = (1.0 / h) * (-u + kp * (gap - r0 - h * v) + kd * (vp - v - h * u) + up)
    return u + du * dt_c


@kernel
def input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy, tax, tay,
             v_cap_i, a_cap_i, pred_i, u_last, dt_c):
    """Member i's model input (control/laws/__init__.py): Ploeg's law behind pred_i, the
    virtual-structure law at the head."""
    if pred_i < 0:
        return platoon.head_input(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                  tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    v, _, _ = motion_at(kind, x, i, speed_in_i)
    u = platoon.accel_of(kind, i, u_last)
    a = accel_at(u, platoon.gap_at(x, i, pred_i, L), v, platoon.speed_of(kind, x, pred_i, u_last),
                 platoon.accel_of(kind, pred_i, u_last), L[i, _H], L[i, _H + 1], L[i, _H + 2],
                 L[i, _H + 3], dt_c)
    return platoon.member_input(a, kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                tvy, tax, tay, v_cap_i, a_cap_i, dt_c)


def pack(cfg):
    """(n, len(PARAMS)) rows from a sim/fleet.py FleetConfig (controller.cacc_ploeg)."""
    return platoon.pack_rows(cfg, "cacc_ploeg", PARAMS[platoon.OWN_AT:], DEFAULTS)
