"""What the platoon laws (ACC, CACC PATH, Ploeg's CACC: docs/platoon_laws.md) share: the gap to
the member ahead, the lane keeping of the lateral loop, the safety caps and the packing of
their parameters.

A platoon law is longitudinal: it gives the member's desired acceleration a_r [m/s^2] from the
gap to its predecessor ``pred_i`` (the member ahead in the column, FleetConfig.pred), the
speeds and, for the CACCs, accelerations received over the radio. The lateral loop is the
virtual structure's own (eqs 2.5-2.10 and the steering-rate loop 3.37) about the slot's
desired point moved along the slot's direction of travel to the member's own along-position:
the member keeps its lane and slot offset, never its slot's along-position. The head of the
column (``pred_i`` < 0) runs the virtual-structure law on its slot: it is the platoon leader.

Law parameter rows (``L``): columns 0-3 are common (k [m/s], k_theta [1/s], CoG to front
bumper [m], CoG to rear bumper [m]), then the ACC block (controller.acc: the ACC law's
parameters, a CACC's fallback), then a CACC's own parameters (:data:`OWN_AT`).
"""
from __future__ import annotations

import numpy as np

from ...core.kernels import kernel, maximum, minimum
from ...models.state import KINEMATIC, motion_at
from ..formation import V_EPS, Target, formation_at
from ...models.bicycle import S
from ..schedule import speed_law, yaw_law
from . import acc_spec, virtual_structure

COMMON = ("k", "k_theta", "front_m", "rear_m")
"""The first columns of every platoon law's parameter rows."""
N_COMMON = len(COMMON)
K, K_THETA, FRONT, REAR = range(N_COMMON)
"""The common columns: k [m/s], k_theta [1/s], CoG to front and to rear bumper [m]."""
ACC_PARAMS = ("headway_s", "gap_gain", "standstill_m")
"""The ACC block that follows (controller.acc): the ACC law's own parameters and a CACC's
fallback on radio loss (sim/fleet_laws.py)."""
ACC_DEFAULTS = acc_spec.DEFAULTS
ACC_AT = N_COMMON
"""First column of the ACC block."""
HEADWAY, GAP_GAIN, STANDSTILL = range(ACC_AT, ACC_AT + len(ACC_PARAMS))
"""The ACC block's columns: h [s], lambda [1/s], r0 [m]."""
OWN_AT = N_COMMON + len(ACC_PARAMS)
"""First column of a CACC's own parameters."""


@kernel
def gap_at(x, i, p, L):
    """Bumper-to-bumper gap [m] from member i to the member p ahead: the centres of gravity's
    distance along i's heading less p's CoG-to-rear and i's CoG-to-front lengths."""
    c = np.cos(x[i, S.PSI])
    s = np.sin(x[i, S.PSI])
    d = (x[p, S.X] - x[i, S.X]) * c + (x[p, S.Y] - x[i, S.Y]) * s
    return d - L[p, REAR] - L[i, FRONT]


@kernel
def speed_of(kind, x, p, u_last):
    """Speed [m/s] of member p as the others see it: its speed state (dynamic model) or its
    last speed input (unicycle)."""
    if kind == KINEMATIC:
        return maximum(u_last[p], 0.0)
    return motion_at(kind, x, p, 0.0)[0]


@kernel
def accel_of(kind, p, u_last):
    """Acceleration [m/s^2] member p sends over the radio: its last desired acceleration a_r
    (dynamic model); 0 for the unicycle, whose input is a speed."""
    if kind == KINEMATIC:
        return 0.0
    return u_last[p]


@kernel
def leader_at(target):
    """Speed [m/s] and acceleration [m/s^2] of the platoon's reference as member i received it:
    its desired point's (``target``: control/formation.py Target) speed and its acceleration along
    it (the virtual car's v and v dot on a straight road; the radio's copy under [comm])."""
    tvx, tvy = target.vx, target.vy
    sp = np.hypot(tvx, tvy)
    if sp < V_EPS:
        return sp, 0.0
    return sp, (target.ax * tvx + target.ay * tvy) / sp


@kernel(inline="always")
def lane_keeping_at(fleet, state, i, target):
    """The lateral loop of a platoon member: (u1, v_ref, omega_ref, theta* dot, v_ref dot, ex,
    ey, heading error). Eqs (2.5)-(2.10) about the desired point shifted along its direction of
    travel by the along error, so only the lateral error steers; u1 is the steering rate of
    (3.37) (dynamic) or omega_ref (unicycle). ex, ey [m] are the error to the slot itself."""
    kind, x, L = fleet.kind, state.x, fleet.L
    px, py, tvx, tvy = target.px, target.py, target.vx, target.vy
    v, r, course = motion_at(kind, x, i, state.speed_in[i])
    sp = np.hypot(tvx, tvy)
    if sp > V_EPS:
        cx = tvx / sp
        cy = tvy / sp
    else:
        cx = np.cos(x[i, S.PSI])
        cy = np.sin(x[i, S.PSI])
    ex = px - x[i, S.X]
    ey = py - x[i, S.Y]
    e_lon = ex * cx + ey * cy
    vr, om, tsd, vrd, _, _, he = formation_at(
        Target(px - e_lon * cx, py - e_lon * cy, tvx, tvy, target.ax, target.ay), x[i, S.X],
        x[i, S.Y], v * np.cos(course), v * np.sin(course), x[i, S.PSI], state.theta_star[i],
        L[i, K], L[i, K_THETA])
    if kind == KINEMATIC:
        return om, vr, om, tsd, vrd, ex, ey, he
    return yaw_law(fleet.gains, i, om, r), vr, om, tsd, vrd, ex, ey, he


@kernel(inline="always")
def member_input(a_r, fleet, state, i, target, v_cap_i, a_cap_i):
    """The model input of a platoon member with longitudinal command a_r [m/s^2]: the law's
    tuple (control/laws/__init__.py). a_r is capped by the safety layer (a_cap, and the speed
    loop 3.32 towards v_cap when the member is faster); the unicycle integrates it into its
    speed input over the control period ``fleet.dt_c`` [s]."""
    speed_in_i = state.speed_in[i]
    v, r, course = motion_at(fleet.kind, state.x, i, speed_in_i)
    a = minimum(a_r, a_cap_i)
    if v > v_cap_i:
        a = minimum(a, speed_law(fleet.gains, i, v_cap_i, v))
    u1, vr, om, tsd, vrd, ex, ey, he = lane_keeping_at(fleet, state, i, target)
    if fleet.kind == KINEMATIC:
        vk = maximum(speed_in_i + a * fleet.dt_c, 0.0)
        return vk, u1, vk, om, tsd, a, ex, ey, he
    return a, u1, vr, om, tsd, vrd, ex, ey, he


@kernel(inline="always")
def head_input(fleet, state, i, target, v_cap_i, a_cap_i):
    """The head of the column: the virtual-structure law on its slot."""
    return virtual_structure.input_at(fleet, state, i, target, v_cap_i, a_cap_i)


def pack_rows(cfg, name: str, params: tuple[str, ...], defaults: dict[str, float]) -> np.ndarray:
    """(n, OWN_AT + len(params)) rows: k, k_theta, the bumper lengths, the ACC block, then law
    ``name``'s parameters from cfg.law_params (one mapping per member, or None: the
    defaults)."""
    n = cfg.n
    k = np.broadcast_to(np.asarray(cfg.k, dtype=float), (n,))
    kt = np.broadcast_to(np.asarray(cfg.k_theta, dtype=float), (n,))
    bump = np.zeros((n, 2)) if cfg.bumpers is None else np.asarray(cfg.bumpers, dtype=float)
    per = cfg.law_params if cfg.law_params is not None else ({},) * n
    acc = np.array([[float(per[i].get("acc", {}).get(p, ACC_DEFAULTS[p])) for p in ACC_PARAMS]
                    for i in range(n)], dtype=float).reshape(n, len(ACC_PARAMS))
    own = np.array([[float(per[i].get(name, {}).get(p, defaults[p])) for p in params]
                    for i in range(n)], dtype=float).reshape(n, len(params))
    return np.column_stack([k, kt, bump, acc, own])
