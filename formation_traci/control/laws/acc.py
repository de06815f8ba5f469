"""ACC: constant time gap on ego sensing only (Plexe's ``_acc``; Rajamani, Vehicle Dynamics and
Control, 2nd ed., ch. 6; docs/platoon_laws.md):

    a_r = -(1 / h) [ (v - v_p) + lambda (h v + r0 - gap) ]

with the gap [m] and the predecessor's speed v_p [m/s] measured by the member's own sensor (its
state row), h the time gap [s], r0 the standstill distance [m], lambda [1/s] the gap gain.
Defaults are Plexe's: h = 1.2 s, lambda (gap_gain) = 0.1 1/s, r0 = 2 m (control/laws/acc_spec.py).
"""
from __future__ import annotations

from ...core.kernels import kernel
from ...models.state import motion_at
from . import platoon
from .acc_spec import DEFAULTS, SPEC  # noqa: F401 (the law's schema and defaults)

PARAMS = (*platoon.COMMON, *platoon.ACC_PARAMS)


@kernel
def accel_at(x, i, p, v, vp, L):
    """The ACC law's a_r [m/s^2] of member i behind p (speeds v, vp [m/s])."""
    h = L[i, platoon.HEADWAY]
    gap = platoon.gap_at(x, i, p, L)
    return -(1.0 / h) * ((v - vp) + L[i, platoon.GAP_GAIN] * (h * v + L[i, platoon.STANDSTILL]
                                                               - gap))


@kernel(inline="always")
def input_at(fleet, state, i, target, v_cap_i, a_cap_i):
    """Member i's model input (control/laws/__init__.py): the ACC law behind its predecessor,
    the virtual-structure law at the head. A CACC member on radio loss runs this law on its
    ACC block (sim/fleet_laws.py)."""
    p = fleet.pred[i]
    if p < 0:
        return platoon.head_input(fleet, state, i, target, v_cap_i, a_cap_i)
    v, _, _ = motion_at(fleet.kind, state.x, i, state.speed_in[i])
    vp = platoon.speed_of(fleet.kind, state.x, p, state.u_last)
    a = accel_at(state.x, i, p, v, vp, fleet.L)
    return platoon.member_input(a, fleet, state, i, target, v_cap_i, a_cap_i)


def pack(cfg):
    """(n, len(PARAMS)) rows from a sim/fleet.py FleetConfig (controller.acc)."""
    return platoon.pack_rows(cfg, "acc", (), DEFAULTS)
