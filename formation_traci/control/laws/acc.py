"""ACC: constant time gap on ego sensing only (Plexe's ``_acc``; Rajamani, Vehicle Dynamics and
Control, 2nd ed., ch. 6; docs/platoon_laws.md):

    a_r = -(1 / h) [ (v - v_p) + lambda (h v + r0 - gap) ]

with the gap [m] and the predecessor's speed v_p [m/s] measured by the member's own sensor (its
state row), h the time gap [s], r0 the standstill distance [m], lambda [1/s] the gap gain.
Defaults are Plexe's: h = 1.2 s, lambda (gap_gain) = 0.1 1/s, r0 = 2 m.
"""
from __future__ import annotations

from ...kernels import kernel
from ...models.state import motion_at
from . import platoon

PARAMS = (*platoon.COMMON, *platoon.ACC_PARAMS)
DEFAULTS = platoon.ACC_DEFAULTS
_H = platoon.ACC_AT


@kernel
def accel_at(x, i, p, v, vp, L):
    """The ACC law's a_r [m/s^2] of member i behind p (speeds v, vp [m/s])."""
    h = L[i, _H]
    gap = platoon.gap_at(x, i, p, L)
    return -(1.0 / h) * ((v - vp) + L[i, _H + 1] * (h * v + L[i, _H + 2] - gap))


@kernel
def input_at(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx, tvy, tax, tay,
             v_cap_i, a_cap_i, pred_i, u_last, dt_c):
    """Member i's model input (control/laws/__init__.py): the ACC law behind pred_i, the
    virtual-structure law at the head. A CACC member on radio loss runs this law on its ACC
    block (sim/fleet_laws.py)."""
    if pred_i < 0:
        return platoon.head_input(kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                  tvy, tax, tay, v_cap_i, a_cap_i, pred_i, u_last, dt_c)
    v, _, _ = motion_at(kind, x, i, speed_in_i)
    vp = platoon.speed_of(kind, x, pred_i, u_last)
    a = accel_at(x, i, pred_i, v, vp, L)
    return platoon.member_input(a, kind, x, i, theta_star_i, speed_in_i, L, gains, px, py, tvx,
                                tvy, tax, tay, v_cap_i, a_cap_i, dt_c)


def pack(cfg):
    """(n, len(PARAMS)) rows from a sim/fleet.py FleetConfig (controller.acc)."""
    return platoon.pack_rows(cfg, "acc", (), DEFAULTS)
