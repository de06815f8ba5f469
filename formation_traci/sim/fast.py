"""Compiled (numba) per-step formation layer: targets, controllers, models, recorded signals.

One SUMO step of ``sim/sumo_loop.py`` runs ``n_ctrl`` control periods, each

    targets (road/targets.py road_targets, control/formation.py rigid_targets)
    -> fleet.control (formation controller 2.5-2.10, speed loop 3.32-3.34, steering-rate
       loop 3.37, the safety layer's v_cap / a_cap)
    -> fleet.advance (RK4 of the vehicles: models/bicycle_fast.py, Euler on theta* 2.11)
    -> the virtual car along the line (sumo_loop._advance_vc),

and records ``fleet.member_signals`` at the start of the step. In numpy each of these is a
few dozen small-array calls (2-4 ms per SUMO step). The kernels below do the same arithmetic
per member in scalar code, in one compiled call per SUMO step:

* :func:`road_targets_nb`, :func:`rigid_targets_nb`, :func:`mixed_targets_nb` (the
  ``sumo_loop._targets`` mix: a boolean mask of road members);
* :func:`control_nb` (``fleet.control``), :func:`kinematics_nb` (``fleet.kinematics``);
* :func:`step_periods_nb` (the inner loop of one SUMO step) and :func:`step_free_nb` (the
  same for free space: the virtual car from its speed and yaw-rate profiles, ``sim/leader.py``);
* :func:`record_signals_nb` / :func:`record_signals_free_nb` (``fleet.member_signals`` into a
  preallocated (n, len(SIGNAL_COLUMNS)) array, NaN where the kinematic model has no value).

:class:`FastFleet` packs a FleetConfig, the road and the slots once and exposes
``step`` / ``signals`` / ``leader_state`` / ``to_frenet`` for the loops.

The formulas are those of the numpy path, written per scalar in the same operation order
(no fastmath), so the two agree to rounding: the only differences are the last ulp of
numpy's SIMD transcendentals versus libm's. ``tests/test_fast_step.py`` runs both side by
side. Keep this file in step with control/formation.py, control/speed.py, control/yaw.py,
control/schedule.py, road/targets.py, road/leader.py, sim/fleet.py, models/bicycle.py and
sim/leader.py / sim/profile.py; :meth:`FastFleet.from_config` checks one control period
and the recorded signals against the numpy path (``verify=True``) and raises
:class:`FastPathMismatch` if they disagree.

Numba's on-disk cache does not notice edits of the modules whose compiled functions these
kernels call (road/fast_line.py, models/bicycle_fast.py); at import this module compares a
digest of those files with the one stored next to its cache and drops its cached kernels
when they changed.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from ..control.formation import COS_WAIT, K_WAIT, V_EPS, FormationOutput, LeaderState, Targets
from ..models import bicycle_fast
from ..models.bicycle_fast import (_bicycle_rhs, _clip, _maximum, _minimum, integrate_bicycle,
                                   integrate_unicycle)
from ..models.params import G
from ..models import resistance
from ..models.resistance import aero_force, road_load
from ..record.columns import TRAJECTORY_COLUMNS
from ..road import fast_line
from ..road.fast_line import FastLine, _wrap, frame_at, to_frenet_many
from .fleet import FleetConfig, FleetState
from .integrate import substeps

# ------------------------------------------------------------------ recorded columns

FILLED_BY_CALLER = ("t", "vehicle_id", "s", "d", "lane_index", "sumo_gap")
"""Trajectory columns :func:`record_signals_nb` does not compute."""

SIGNAL_COLUMNS: tuple[str, ...] = tuple(c.name for c in TRAJECTORY_COLUMNS
                                        if c.name not in FILLED_BY_CALLER)
"""Columns of the signals array, in the order of record/columns.py TRAJECTORY_COLUMNS."""

_KERNEL_SIGNALS = ("x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "ex", "ey",
                   "e_lon", "e_lat", "x_des", "y_des", "v_ref", "omega_ref", "steer",
                   "steer_rate", "beta", "slip_front", "slip_rear", "traction_force",
                   "traction_force_max", "friction_usage", "power", "drag_force", "drag_ratio")
"""The signals the kernel computes, in its internal slot order (slot k -> _Q_* below)."""
(_Q_X, _Q_Y, _Q_HEADING, _Q_V, _Q_YAW_RATE, _Q_A_LON, _Q_A_LAT, _Q_EX, _Q_EY, _Q_E_LON,
 _Q_E_LAT, _Q_X_DES, _Q_Y_DES, _Q_V_REF, _Q_OMEGA_REF, _Q_STEER, _Q_STEER_RATE, _Q_BETA,
 _Q_SLIP_F, _Q_SLIP_R, _Q_TRACTION, _Q_TRACTION_MAX, _Q_FRICTION, _Q_POWER, _Q_DRAG,
 _Q_DRAG_RATIO) = range(26)
_N_Q = 26


def signal_column_map(columns: tuple[str, ...] = SIGNAL_COLUMNS) -> np.ndarray:
    """Output column of every kernel slot (-1: not recorded), for the kernels' ``cols``."""
    return np.array([columns.index(n) if n in columns else -1 for n in _KERNEL_SIGNALS],
                    dtype=np.int64)


# --------------------------------------------------------------------- packed inputs
# C: float64 constants (runtime values, so that numba's cache never freezes them)
_C_SG_MIN, _C_SG_MAX, _C_SK_MIN, _C_YG_MIN, _C_YG_MAX, _C_YK_MIN, _C_V_EPS, _C_G = range(8)
N_CONSTS = 8

# FO: formation controller output columns (FormationOutput fields; v_ref after v_cap)
FO_V_REF, FO_OMEGA_REF, FO_THETA_STAR_DOT, FO_V_REF_DOT, FO_EX, FO_EY, FO_HEADING_ERROR = range(7)
N_FO = 7
# T: targets columns: p (x, y), v (x, y), a (x, y)
N_T = 6

MODEL_KINEMATIC = 0
MODEL_DYNAMIC = 1


def pack_consts(cfg: FleetConfig) -> np.ndarray:
    sg, yg = cfg.speed_gains, cfg.yaw_gains
    return np.array([sg.g_min, sg.g_max, sg.k_min, yg.g_min, yg.g_max, yg.k_min, V_EPS, G],
                    dtype=np.float64)


def pack_profiles(speed, yaw_rate) -> np.ndarray:
    """Two sim.profile.Profile as one array: [n_v, n_w, smooth_v, smooth_w, t_v, v_v, t_w, v_w]."""
    for p in (speed, yaw_rate):
        if p.interp not in ("linear", "smooth"):
            raise ValueError(f"unknown profile interpolation {p.interp!r}")
    return np.concatenate([[len(speed.t), len(yaw_rate.t), speed.interp == "smooth",
                            yaw_rate.interp == "smooth"], speed.t, speed.values, yaw_rate.t,
                           yaw_rate.values]).astype(np.float64)


# Kernel layout: the public kernels index the arrays; everything they call takes and returns
# scalars (plus the one line buffer G), so numba's reference counting stays out of the loops.

# ------------------------------------------------------------------ scalar helpers

@njit(cache=True, error_model="numpy")
def _gain(e, g_min, g_max, k_min):
    """control/schedule.py gain: (G_max - G_min) exp(-|e| K_min) + G_min."""
    return (g_max - g_min) * np.exp(-np.abs(e) * k_min) + g_min


@njit(cache=True, error_model="numpy")
def _advance_vc(s, v, a, dt):
    """sumo_loop._advance_vc: constant acceleration along the line, stop at v = 0."""
    if v + a * dt >= 0.0:
        return s + v * dt + 0.5 * a * dt * dt, v + a * dt
    t_stop = v / -a
    return s + v * t_stop + 0.5 * a * t_stop * t_stop, 0.0


@njit(cache=True, error_model="numpy")
def _road_leader(G, s, v, v_dot):
    """road/leader.py road_leader_state: (x, y, theta, v, omega, v_dot, omega_dot)."""
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s)
    return x, y, heading, v, v * kappa, v_dot, v_dot * kappa + v ** 2 * kappa_rate


@njit(cache=True, error_model="numpy")
def _road_target(G, s, v, v_dot, dx, dy):
    """road/targets.py road_targets for one slot (dx, dy): (px, py, vx, vy, ax, ay)."""
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s + dx)
    nx = -ty
    ny = tx
    stretch = 1.0 - dy * kappa
    vs = v * stretch
    ct = v_dot * stretch - v * v * dy * kappa_rate
    cn = v * v * stretch * kappa
    return (x + dy * nx, y + dy * ny, vs * tx, vs * ty, ct * tx + cn * nx, ct * ty + cn * ny)


@njit(cache=True, error_model="numpy")
def _rigid_target(X, Y, th, v, om, v_dot, om_dot, dx, dy):
    """control/formation.py rigid_targets (eq 2.4) for one offset: (px, py, vx, vy, ax, ay)."""
    c = np.cos(th)
    s = np.sin(th)
    rdx = dx * c - dy * s
    rdy = dx * s + dy * c
    rjx = -dx * s - dy * c
    rjy = dx * c - dy * s
    vo = v * om
    om2 = om ** 2
    return (X + rdx, Y + rdy, v * c + om * rjx, v * s + om * rjy,
            v_dot * c + vo * -s + om_dot * rjx - om2 * rdx,
            v_dot * s + vo * c + om_dot * rjy - om2 * rdy)


@njit(cache=True, error_model="numpy")
def _formation(px, py, tvx, tvy, tax, tay, X, Y, velx, vely, heading, theta_star, k, k_theta,
               v_eps):
    """control/formation.py formation_control, eqs (2.5)-(2.10), for one member:
    (v_ref, omega_ref, theta_star_dot, v_ref_dot, ex, ey, heading_error)."""
    ex = px - X
    ey = py - Y
    tlx = tvx + k * np.tanh(ex)
    tly = tvy + k * np.tanh(ey)
    chx = np.cosh(ex)
    chy = np.cosh(ey)
    tldx = tax + k * (1.0 / (chx * chx)) * (tvx - velx)
    tldy = tay + k * (1.0 / (chy * chy)) * (tvy - vely)
    v_ref = np.hypot(tlx, tly)
    v_safe = _maximum(v_ref, v_eps)
    tsd = (-tldx * tly + tldy * tlx) / (v_safe * v_safe)
    he = _wrap(theta_star - heading)
    omega_ref = tsd + k_theta * he
    v_ref_dot = (tlx * tldx + tly * tldy) / v_safe
    # no turning around (formation.py): fade into waiting when (x~, y~) points away
    w = _clip((tlx * np.cos(heading) + tly * np.sin(heading)) / v_safe / COS_WAIT, 0.0, 1.0)
    if w < 1.0:
        v_ref = w * v_ref
        omega_ref = w * omega_ref
        v_ref_dot = w * v_ref_dot
        tsd = w * tsd - (1.0 - w) * K_WAIT * np.sin(theta_star - heading)
    return (v_ref, omega_ref, tsd, v_ref_dot, ex, ey, he)


@njit(cache=True, error_model="numpy")
def _inputs(model_kind, v_ref, omega_ref, v, r, v_cap, a_cap, C0, C1, C2, C3, C4, C5):
    """fleet.control after the formation controller: v_cap on v_ref, then the model input
    (kinematic: v_ref, omega_ref; dynamic: a_r = K(e) e (3.32-3.34) capped by a_cap and
    delta dot = K(e) e (3.37)). Returns (u0, u1, capped v_ref)."""
    v_ref = _minimum(v_ref, v_cap)
    if model_kind == MODEL_KINEMATIC:
        return v_ref, omega_ref, v_ref
    e = v_ref - v
    a_r = _minimum(_gain(e, C0, C1, C2) * e, a_cap)
    ew = omega_ref - r
    return a_r, _gain(ew, C3, C4, C5) * ew, v_ref


@njit(cache=True, error_model="numpy")
def _profile(prof, which, t):
    """sim/profile.py Profile.__call__ of profile ``which`` (0: speed, 1: yaw rate) packed by
    pack_profiles: value and derivative at t."""
    nv = int(prof[0])
    nw = int(prof[1])
    if which == 0:
        n = nv
        smooth = prof[2] != 0.0
        ot = 4
        ov = 4 + nv
    else:
        n = nw
        smooth = prof[3] != 0.0
        ot = 4 + 2 * nv
        ov = 4 + 2 * nv + nw
    if n == 1 or t <= prof[ot]:
        return prof[ov], 0.0
    if t >= prof[ot + n - 1]:
        return prof[ov + n - 1], 0.0
    i = 0  # np.searchsorted(ts, t, side="right") - 1
    while i + 1 < n and prof[ot + i + 1] <= t:
        i += 1
    t0 = prof[ot + i]
    t1 = prof[ot + i + 1]
    v0 = prof[ov + i]
    v1 = prof[ov + i + 1]
    span = t1 - t0
    s = (t - t0) / span
    if not smooth:
        return v0 + (v1 - v0) * s, (v1 - v0) / span
    return v0 + (v1 - v0) * s * s * (3.0 - 2.0 * s), (v1 - v0) * 6.0 * s * (1.0 - s) / span


@njit(cache=True, error_model="numpy")
def _free_leader_advance(prof, t, X, Y, th, dt, n_sub):
    """sim/leader.py FreeLeader.advance: RK4 of eq (2.3) over dt in n_sub sub-steps."""
    h = dt / n_sub
    for i in range(n_sub):
        t0 = t + i * h
        v1 = _profile(prof, 0, t0)[0]
        w1 = _profile(prof, 1, t0)[0]
        k1x, k1y, k1t = v1 * math.cos(th), v1 * math.sin(th), w1
        th2 = th + h / 2 * k1t
        v2 = _profile(prof, 0, t0 + h / 2)[0]
        w2 = _profile(prof, 1, t0 + h / 2)[0]
        k2x, k2y, k2t = v2 * math.cos(th2), v2 * math.sin(th2), w2
        th3 = th + h / 2 * k2t
        k3x, k3y, k3t = v2 * math.cos(th3), v2 * math.sin(th3), w2
        th4 = th + h * k3t
        v4 = _profile(prof, 0, t0 + h)[0]
        w4 = _profile(prof, 1, t0 + h)[0]
        k4x, k4y, k4t = v4 * math.cos(th4), v4 * math.sin(th4), w4
        X += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        Y += h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y)
        th += h / 6 * (k1t + 2 * k2t + 2 * k3t + k4t)
    return X, Y, th


# --------------------------------------------------------------- public kernels

@njit(cache=True, error_model="numpy")
def road_targets_nb(G, s, v, v_dot, offsets):
    """road_targets(line, s, v, v_dot, offsets) as an (n, 6) array [p | v | a]."""
    n = offsets.shape[0]
    T = np.empty((n, N_T))
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _road_target(
            G, s, v, v_dot, offsets[i, 0], offsets[i, 1])
    return T


@njit(cache=True, error_model="numpy")
def rigid_targets_nb(vc, offsets):
    """rigid_targets(LeaderState(*vc), offsets) as an (n, 6) array; vc = (x, y, theta, v,
    omega, v_dot, omega_dot)."""
    n = offsets.shape[0]
    T = np.empty((n, N_T))
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _rigid_target(
            vc[0], vc[1], vc[2], vc[3], vc[4], vc[5], vc[6], offsets[i, 0], offsets[i, 1])
    return T


@njit(cache=True, error_model="numpy")
def mixed_targets_nb(G, slots, rigid, is_road, s, v, v_dot):
    """sumo_loop._targets(road, slots, rigid, is_road, s, v, v_dot) as an (n, 6) array
    (slots / rigid with NaN rows replaced by 0, as _targets does)."""
    n = slots.shape[0]
    T = np.empty((n, N_T))
    X, Y, th, vv, om, vd, omd = _road_leader(G, s, v, v_dot)
    for i in range(n):
        if is_road[i]:
            T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _road_target(
                G, s, v, v_dot, slots[i, 0], slots[i, 1])
        else:
            T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _rigid_target(
                X, Y, th, vv, om, vd, omd, rigid[i, 0], rigid[i, 1])
    return T


@njit(cache=True, error_model="numpy")
def kinematics_nb(x, speed_in, model_kind):
    """fleet.kinematics: position (n, 2), velocity (n, 2), heading (n,)."""
    n = x.shape[0]
    pos = np.empty((n, 2))
    vel = np.empty((n, 2))
    hd = np.empty(n)
    for i in range(n):
        psi = x[i, 2]
        if model_kind == MODEL_KINEMATIC:
            v = speed_in[i]
            course = psi
        else:
            v = x[i, 3]
            course = psi + x[i, 4]
        pos[i, 0] = x[i, 0]
        pos[i, 1] = x[i, 1]
        vel[i, 0] = v * np.cos(course)
        vel[i, 1] = v * np.sin(course)
        hd[i] = psi
    return pos, vel, hd


@njit(cache=True, error_model="numpy")
def _control_at(i, x, theta_star, speed_in, model_kind, k, k_theta, C, px, py, tvx, tvy, tax,
                tay, v_cap_i, a_cap_i):
    """Formation controller and model input of member i for its desired point (p, v, a):
    (u0, u1, capped v_ref, omega_ref, theta* dot, v_ref dot, ex, ey, heading error, v, r)."""
    psi = x[i, 2]
    if model_kind == MODEL_KINEMATIC:
        v = speed_in[i]
        r = 0.0
        course = psi
    else:
        v = x[i, 3]
        r = x[i, 5]
        course = psi + x[i, 4]
    vr, om, tsd, vrd, ex, ey, he = _formation(
        px, py, tvx, tvy, tax, tay, x[i, 0], x[i, 1], v * np.cos(course), v * np.sin(course),
        psi, theta_star[i], k[i], k_theta[i], C[_C_V_EPS])
    u0, u1, vr = _inputs(model_kind, vr, om, v, r, v_cap_i, a_cap_i,
                         C[0], C[1], C[2], C[3], C[4], C[5])
    return u0, u1, vr, om, tsd, vrd, ex, ey, he, v, r


@njit(cache=True, error_model="numpy")
def _member_control(i, x, theta_star, speed_in, model_kind, k, k_theta, C, T, v_cap, a_cap):
    """_control_at with member i's targets from row i of T (columns p, v, a)."""
    return _control_at(i, x, theta_star, speed_in, model_kind, k, k_theta, C, T[i, 0], T[i, 1],
                        T[i, 2], T[i, 3], T[i, 4], T[i, 5], v_cap[i], a_cap[i])


@njit(cache=True, error_model="numpy")
def control_nb(x, theta_star, speed_in, model_kind, k, k_theta, C, T, v_cap, a_cap):
    """fleet.control(cfg, state, Targets(T[:, :2], T[:, 2:4], T[:, 4:]), v_cap, a_cap):
    returns u (n, 2) and the controller output (n, 7), columns FO_*. No cap: pass +inf."""
    n = x.shape[0]
    U = np.empty((n, 2))
    FO = np.empty((n, N_FO))
    for i in range(n):
        U[i, 0], U[i, 1], vr, om, tsd, vrd, ex, ey, he, v, r = _member_control(
            i, x, theta_star, speed_in, model_kind, k, k_theta, C, T, v_cap, a_cap)
        FO[i, 0] = vr
        FO[i, 1] = om
        FO[i, 2] = tsd
        FO[i, 3] = vrd
        FO[i, 4] = ex
        FO[i, 5] = ey
        FO[i, 6] = he
    return U, FO


@njit(cache=True, error_model="numpy")
def _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub):
    """fleet.advance over one control period: theta* by Euler (in place), RK4 of the vehicles,
    the unicycle's applied speed (in place). Returns the new states."""
    for i in range(x.shape[0]):
        theta_star[i] = theta_star[i] + tsd[i] * dt_c
    if model_kind == MODEL_KINEMATIC:
        x = integrate_unicycle(x, U, dt_c, n_sub)
        for i in range(x.shape[0]):
            speed_in[i] = _maximum(U[i, 0], 0.0)
        return x
    return integrate_bicycle(x, U, P, dt_c, n_sub)


@njit(cache=True, error_model="numpy")
def step_periods_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                    is_road, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl, n_sub):
    """The inner loop of one SUMO step (sumo_loop.sumo_steps): ``n_ctrl`` periods of
    targets (sumo_loop._targets) -> fleet.control -> fleet.advance -> _advance_vc.
    Inputs are not modified. Returns (x, theta_star, speed_in, s_vc, v_vc) after the step."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    U = np.empty((n, 2))
    tsd = np.empty(n)
    any_rigid = False
    for i in range(n):
        if not is_road[i]:
            any_rigid = True
    X0 = Y0 = th0 = v0 = om0 = vd0 = omd0 = 0.0
    for _ in range(n_ctrl):
        if any_rigid:
            X0, Y0, th0, v0, om0, vd0, omd0 = _road_leader(G, s_vc, v_vc, a_vc)
        for i in range(n):
            if is_road[i]:
                px, py, tvx, tvy, tax, tay = _road_target(G, s_vc, v_vc, a_vc, slots[i, 0],
                                                          slots[i, 1])
            else:
                px, py, tvx, tvy, tax, tay = _rigid_target(X0, Y0, th0, v0, om0, vd0, omd0,
                                                           rigid[i, 0], rigid[i, 1])
            U[i, 0], U[i, 1], _, _, tsd[i], _, _, _, _, _, _ = _control_at(
                i, x, theta_star, speed_in, model_kind, k, k_theta, C, px, py, tvx, tvy, tax,
                tay, v_cap[i], a_cap[i])
        x = _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub)
        s_vc, v_vc = _advance_vc(s_vc, v_vc, a_vc, dt_c)
    return x, theta_star, speed_in, s_vc, v_vc


@njit(cache=True, error_model="numpy")
def step_free_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, offsets, prof, t,
                 pose, dt_c, n_ctrl, n_sub, n_sub_leader):
    """The inner loop of one free-space step (runner.free_space_steps): per period the
    virtual car sampled from its profiles at t + j dt_c, rigid targets, control (no caps),
    advance, then the leader's pose by RK4. Returns (x, theta_star, speed_in, pose)."""
    n = x.shape[0]
    theta_star = theta_star.copy()
    speed_in = speed_in.copy()
    U = np.empty((n, 2))
    tsd = np.empty(n)
    X, Y, th = pose[0], pose[1], pose[2]
    inf = np.inf
    for j in range(n_ctrl):
        tc = t + j * dt_c
        vl, vl_dot = _profile(prof, 0, tc)
        w, w_dot = _profile(prof, 1, tc)
        for i in range(n):
            px, py, tvx, tvy, tax, tay = _rigid_target(X, Y, th, vl, w, vl_dot, w_dot,
                                                       offsets[i, 0], offsets[i, 1])
            U[i, 0], U[i, 1], _, _, tsd[i], _, _, _, _, _, _ = _control_at(
                i, x, theta_star, speed_in, model_kind, k, k_theta, C, px, py, tvx, tvy, tax,
                tay, inf, inf)
        x = _advance_members(x, theta_star, speed_in, U, tsd, model_kind, P, dt_c, n_sub)
        X, Y, th = _free_leader_advance(prof, tc, X, Y, th, dt_c, n_sub_leader)
    out_pose = np.empty(3)
    out_pose[0] = X
    out_pose[1] = Y
    out_pose[2] = th
    return x, theta_star, speed_in, out_pose


@njit(cache=True, error_model="numpy")
def _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                 vc_theta, cols, out):
    """fleet.control + fleet.member_signals for targets T into out[i, cols[slot]]."""
    n = x.shape[0]
    c = np.cos(vc_theta)
    s = np.sin(vc_theta)
    g = C[_C_G]
    vals = np.empty(_N_Q)
    for i in range(n):
        psi = x[i, 2]
        u0, u1, vr, om, tsd, vrd, ex, ey, he, v, r = _member_control(
            i, x, theta_star, speed_in, model_kind, k, k_theta, C, T, v_cap, a_cap)
        vals[_Q_X] = x[i, 0]
        vals[_Q_Y] = x[i, 1]
        vals[_Q_HEADING] = psi
        vals[_Q_EX] = ex
        vals[_Q_EY] = ey
        vals[_Q_E_LON] = c * ex + s * ey
        vals[_Q_E_LAT] = -s * ex + c * ey
        vals[_Q_X_DES] = T[i, 0]
        vals[_Q_Y_DES] = T[i, 1]
        vals[_Q_V_REF] = vr
        vals[_Q_OMEGA_REF] = om
        if model_kind == MODEL_KINEMATIC:
            vk = _maximum(u0, 0.0)
            vals[_Q_V] = vk
            vals[_Q_YAW_RATE] = u1
            vals[_Q_A_LON] = vrd
            vals[_Q_A_LAT] = vk * u1
            for q in (_Q_STEER, _Q_STEER_RATE, _Q_BETA, _Q_SLIP_F, _Q_SLIP_R, _Q_TRACTION,
                      _Q_TRACTION_MAX, _Q_FRICTION, _Q_POWER, _Q_DRAG, _Q_DRAG_RATIO):
                vals[q] = np.nan
        else:
            beta = x[i, 4]
            delta = x[i, 6]
            # models/bicycle.py _forces (slip angles, cornering forces, clipped traction)
            m = P[i, bicycle_fast._M]
            a = P[i, bicycle_fast._A]
            b = P[i, bicycle_fast._B]
            h = P[i, bicycle_fast._H]
            mu = P[i, bicycle_fast._MU]
            vs = _maximum(v, P[i, bicycle_fast._VLOW])
            vx = vs * np.cos(beta)
            vy = vs * np.sin(beta)
            alpha_f = np.arctan2(vy + a * r, vx) - delta
            alpha_r = np.arctan2(vy - b * r, vx)
            Bf = P[i, bicycle_fast._BF]
            Cf = P[i, bicycle_fast._CF]
            Df = P[i, bicycle_fast._DF]
            Br = P[i, bicycle_fast._BR]
            Cr = P[i, bicycle_fast._CR]
            Dr = P[i, bicycle_fast._DR]
            if P[i, bicycle_fast._LIN] != 0.0:  # models/tire.py cornering_force
                fcf = Bf * Cf * Df * alpha_f
                fcr = Br * Cr * Dr * alpha_r
            else:
                Ef = P[i, bicycle_fast._EF]
                Er = P[i, bicycle_fast._ER]
                ba = Bf * alpha_f
                fcf = Df * np.sin(Cf * np.arctan(ba - Ef * (ba - np.arctan(ba))))
                ba = Br * alpha_r
                fcr = Dr * np.sin(Cr * np.arctan(ba - Er * (ba - np.arctan(ba))))
            L_ = a + b
            f_rl = 0.01 * (1.0 + v / 40.8)
            f_max = mu * (m * g) * (b + f_rl * h) / L_ / (1.0 + mu * h / L_)
            num = m * u0 - fcf * (np.cos(delta) * np.sin(beta) - np.sin(delta) * np.cos(beta)) \
                - fcr * np.sin(beta)
            res_on = P[i, bicycle_fast._RES] != 0.0
            if res_on:  # models/bicycle.py resistance_force (docs/energy.md)
                num = num + _road_load_row(v, P, i)
            den = np.cos(delta) * np.cos(beta) + np.sin(delta) * np.sin(beta)
            f_lf = _clip(num / den, -(mu * m * g), f_max)
            # models/bicycle.py outputs: accelerations from the state derivative
            d = _bicycle_rhs(psi, v, beta, r, delta, u0, u1, P, i)
            course_rate = d[4] + r
            a_lon = d[3] * np.cos(beta) - v * np.sin(beta) * course_rate
            a_lat = d[3] * np.sin(beta) + v * np.cos(beta) * course_rate
            vals[_Q_V] = v
            vals[_Q_YAW_RATE] = r
            vals[_Q_A_LON] = a_lon
            vals[_Q_A_LAT] = a_lat
            vals[_Q_STEER] = delta
            vals[_Q_STEER_RATE] = d[6]
            vals[_Q_BETA] = beta
            vals[_Q_SLIP_F] = alpha_f
            vals[_Q_SLIP_R] = alpha_r
            vals[_Q_TRACTION] = f_lf
            vals[_Q_TRACTION_MAX] = f_max
            vals[_Q_FRICTION] = np.hypot(a_lon, a_lat) / (mu * g)
            # models/bicycle.py energy_outputs
            vals[_Q_POWER] = f_lf * (v * np.cos(beta) * np.cos(delta)
                                     + (v * np.sin(beta) + a * r) * np.sin(delta))
            vals[_Q_DRAG] = _drag_row(v, P, i) if res_on else np.nan
            vals[_Q_DRAG_RATIO] = P[i, bicycle_fast._DRAG] if res_on else np.nan
        for q in range(_N_Q):
            if cols[q] >= 0:
                out[i, cols[q]] = vals[q]


@njit(cache=True, error_model="numpy")
def _road_load_row(v, P, i):
    """models/resistance.py road_load for packed row i."""
    return road_load(v, P[i, bicycle_fast._M], P[i, bicycle_fast._CD], P[i, bicycle_fast._AREA],
                     P[i, bicycle_fast._RHO], P[i, bicycle_fast._DRAG], P[i, bicycle_fast._GRADE])


@njit(cache=True, error_model="numpy")
def _drag_row(v, P, i):
    """models/resistance.py aero_force for packed row i."""
    return aero_force(v, P[i, bicycle_fast._CD], P[i, bicycle_fast._AREA], P[i, bicycle_fast._RHO],
                      P[i, bicycle_fast._DRAG])


@njit(cache=True, error_model="numpy")
def record_signals_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, G, slots, rigid,
                      is_road, s_vc, v_vc, a_vc, v_cap, a_cap, cols, out):
    """fleet.member_signals at the start of a SUMO step (targets and control as in the
    step's first period) into out (n, n_cols), columns via cols (signal_column_map)."""
    T = mixed_targets_nb(G, slots, rigid, is_road, s_vc, v_vc, a_vc)
    vc_theta = frame_at(G, s_vc)[4]
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, v_cap, a_cap,
                 vc_theta, cols, out)


@njit(cache=True, error_model="numpy")
def record_signals_free_nb(x, theta_star, speed_in, model_kind, P, k, k_theta, C, offsets,
                           prof, t, pose, cols, out):
    """fleet.member_signals at the start of a free-space step into out."""
    n = x.shape[0]
    T = np.empty((n, N_T))
    v, v_dot = _profile(prof, 0, t)
    w, w_dot = _profile(prof, 1, t)
    for i in range(n):
        T[i, 0], T[i, 1], T[i, 2], T[i, 3], T[i, 4], T[i, 5] = _rigid_target(
            pose[0], pose[1], pose[2], v, w, v_dot, w_dot, offsets[i, 0], offsets[i, 1])
    inf = np.full(n, np.inf)
    _signal_rows(x, theta_star, speed_in, model_kind, P, k, k_theta, C, T, inf, inf,
                 pose[2], cols, out)


# ------------------------------------------------------------------ the fleet helper

class FastPathMismatch(RuntimeError):
    """The compiled kernels disagree with the numpy reference path."""


def _f64(a) -> np.ndarray:
    """a as a C-contiguous, writeable float64 array (no copy when it already is one: numba
    compiles a separate specialisation for read-only arrays)."""
    if (type(a) is np.ndarray and a.dtype == np.float64 and a.flags.c_contiguous
            and a.flags.writeable):
        return a
    return np.array(a, dtype=np.float64, order="C")


@dataclass
class FastFleet:
    """Everything the kernels need, packed once from a FleetConfig, the road and the slots.

    Road (SUMO) runs::

        ff = FastFleet.from_config(cfg, line, plan.slots, plan.rigid, plan.is_road)
        state, s_vc, v_vc = ff.step(state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl)
        sig = ff.signals(state, s_vc, v_vc, a_vc, v_cap, a_cap)  # (n, len(SIGNAL_COLUMNS))

    Free space::

        ff = FastFleet.free_space(cfg, offsets, leader)
        state, pose = ff.step_free(state, t, pose, dt_c, n_ctrl)
        sig = ff.signals_free(state, t, pose)
    """

    cfg: FleetConfig
    model_kind: int
    P: np.ndarray  # (n, N_PARAMS) packed bicycle parameters (zeros for the unicycle)
    k: np.ndarray
    k_theta: np.ndarray
    C: np.ndarray  # constants, _C_*
    cols: np.ndarray  # signal_column_map()
    line: FastLine | None = None
    slots: np.ndarray | None = None  # (n, 2), NaN -> 0 (as sumo_loop._targets)
    rigid: np.ndarray | None = None  # (n, 2), NaN -> 0
    is_road: np.ndarray | None = None  # (n,) bool
    profiles: np.ndarray | None = None  # free space: pack_profiles(speed, yaw_rate)
    leader_max_step: float = 0.0

    # ---------------------------------------------------------------- construction
    @classmethod
    def _base(cls, cfg: FleetConfig, **kw) -> "FastFleet":
        n = cfg.n
        if cfg.model == "dynamic":  # a copy: set_road_load writes two of its columns
            kind, P = MODEL_DYNAMIC, np.array(cfg.packed, dtype=np.float64, order="C")
        elif cfg.model == "kinematic":
            kind, P = MODEL_KINEMATIC, np.zeros((n, bicycle_fast.N_PARAMS))
        else:
            raise ValueError(f"unknown model {cfg.model!r}")
        k = _f64(np.broadcast_to(np.asarray(cfg.k, dtype=float), (n,)))
        kt = _f64(np.broadcast_to(np.asarray(cfg.k_theta, dtype=float), (n,)))
        return cls(cfg, kind, P, k, kt, pack_consts(cfg), signal_column_map(), **kw)

    @classmethod
    def from_config(cls, cfg: FleetConfig, line, slots, rigid, is_road,
                    verify: bool = True) -> "FastFleet":
        """Road runs: ``line`` a ReferenceLine (or a FastLine), slots / rigid (n, 2) with NaN
        rows for the other kind, is_road (n,) bool (sumo_loop.RoadPlan fields).

        ``verify``: compare one control period and the signals with the numpy path on a
        synthetic state of this fleet on this line (~2 ms); FastPathMismatch if they differ.
        """
        ref_line = None
        if not isinstance(line, FastLine):
            ref_line = line
            line = FastLine.from_reference_line(line)
        n = cfg.n
        is_road = np.ascontiguousarray(np.broadcast_to(np.asarray(is_road, dtype=bool), (n,)))
        ff = cls._base(cfg, line=line, slots=_f64(np.nan_to_num(np.asarray(slots, float))),
                       rigid=_f64(np.nan_to_num(np.asarray(rigid, float))), is_road=is_road)
        if verify and ref_line is not None:
            _verify_road(ff, ref_line, np.asarray(slots, float), np.asarray(rigid, float))
        return ff

    @classmethod
    def free_space(cls, cfg: FleetConfig, offsets, leader, verify: bool = True) -> "FastFleet":
        """Free-space runs: rigid ``offsets`` (n, 2) behind a sim.leader.FreeLeader."""
        prof = pack_profiles(leader.speed, leader.yaw_rate)
        ff = cls._base(cfg, rigid=_f64(offsets), profiles=prof,
                       leader_max_step=float(leader.max_step))
        if verify:
            _verify_free(ff, leader, np.asarray(offsets, float))
        return ff

    # ----------------------------------------------------------------- per step
    @property
    def resistances(self) -> bool:
        """True when the members drive against rolling, aerodynamic and grade resistance."""
        return self.model_kind == MODEL_DYNAMIC and bool(self.cfg.params.resistances)

    def set_road_load(self, drag_ratio, grade=None) -> None:
        """Hold the members' drag ratio [-] (models/drag_interaction.py) and road grade [rad]
        for the next step and signals (arrays (n,) or scalars). No-op without resistances."""
        if not self.resistances:
            return
        self.P[:, bicycle_fast._DRAG] = drag_ratio
        if grade is not None:
            self.P[:, bicycle_fast._GRADE] = grade

    def _caps(self, v_cap, a_cap):
        n = self.cfg.n
        inf = None
        if v_cap is None or a_cap is None:
            inf = np.full(n, np.inf)
        v_cap = inf if v_cap is None else _f64(v_cap)
        a_cap = inf if a_cap is None else _f64(a_cap)
        return v_cap, a_cap

    def step(self, state: FleetState, s_vc: float, v_vc: float, a_vc: float, v_cap, a_cap,
             dt_c: float, n_ctrl: int):
        """One SUMO step: returns (FleetState, s_vc, v_vc) after ``n_ctrl`` periods of dt_c."""
        v_cap, a_cap = self._caps(v_cap, a_cap)
        n_sub = substeps(dt_c, self.cfg.physics_step)
        x, ts, sp, s_vc, v_vc = step_periods_nb(
            _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), self.model_kind,
            self.P, self.k, self.k_theta, self.C, self.line.G, self.slots, self.rigid,
            self.is_road, float(s_vc), float(v_vc), float(a_vc), v_cap, a_cap, float(dt_c),
            int(n_ctrl), n_sub)
        return FleetState(x, ts, sp), s_vc, v_vc

    def signals(self, state: FleetState, s_vc: float, v_vc: float, a_vc: float, v_cap=None,
                a_cap=None, out: np.ndarray | None = None) -> np.ndarray:
        """fleet.member_signals at the start of a SUMO step as an (n, len(SIGNAL_COLUMNS))
        array (columns SIGNAL_COLUMNS)."""
        v_cap, a_cap = self._caps(v_cap, a_cap)
        if out is None:
            out = np.full((self.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
        record_signals_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                          self.model_kind, self.P, self.k, self.k_theta, self.C,
                          self.line.G, self.slots, self.rigid, self.is_road, float(s_vc),
                          float(v_vc), float(a_vc), v_cap, a_cap, self.cols, out)
        return out

    def step_free(self, state: FleetState, t: float, pose, dt_c: float, n_ctrl: int):
        """One free-space step from time t: returns (FleetState, pose)."""
        n_sub = substeps(dt_c, self.cfg.physics_step)
        n_sub_l = substeps(dt_c, self.leader_max_step)
        x, ts, sp, pose = step_free_nb(
            _f64(state.x), _f64(state.theta_star), _f64(state.speed_in), self.model_kind,
            self.P, self.k, self.k_theta, self.C, self.rigid, self.profiles, float(t),
            _f64(pose), float(dt_c), int(n_ctrl), n_sub, n_sub_l)
        return FleetState(x, ts, sp), (float(pose[0]), float(pose[1]), float(pose[2]))

    def signals_free(self, state: FleetState, t: float, pose,
                     out: np.ndarray | None = None) -> np.ndarray:
        if out is None:
            out = np.full((self.cfg.n, len(SIGNAL_COLUMNS)), np.nan)
        record_signals_free_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                               self.model_kind, self.P, self.k, self.k_theta, self.C,
                               self.rigid, self.profiles, float(t), _f64(pose), self.cols, out)
        return out

    # ---------------------------------------------------------------- helpers
    def leader_state(self, s_vc: float, v_vc: float, a_vc: float) -> LeaderState:
        """road_leader_state(line, s_vc, v_vc, a_vc) (for Recorder.add_vc)."""
        return LeaderState(*(float(q) for q in _road_leader(self.line.G, float(s_vc),
                                                             float(v_vc), float(a_vc))))

    def to_frenet(self, xy, s_guess=None):
        """line.to_frenet(xy) for xy (n, 2); s_guess (n,) (e.g. last step's s) only speeds
        the search up."""
        return self.line.to_frenet(xy, s_guess)

    def kinematics(self, state: FleetState):
        """fleet.kinematics(cfg, state): pos (n, 2), vel (n, 2), heading (n,)."""
        return kinematics_nb(_f64(state.x), _f64(state.speed_in), self.model_kind)

    def targets(self, s_vc: float, v_vc: float, a_vc: float) -> Targets:
        """sumo_loop._targets as a Targets."""
        T = mixed_targets_nb(self.line.G, self.slots, self.rigid, self.is_road,
                             float(s_vc), float(v_vc), float(a_vc))
        return Targets(T[:, 0:2], T[:, 2:4], T[:, 4:6])

    def control(self, state: FleetState, targets: Targets, v_cap=None, a_cap=None):
        """fleet.control(cfg, state, targets, v_cap, a_cap): (u, FormationOutput)."""
        v_cap, a_cap = self._caps(v_cap, a_cap)
        T = _f64(np.concatenate([targets.p, targets.v, targets.a], axis=1))
        u, fo = control_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                           self.model_kind, self.k, self.k_theta, self.C, T, v_cap, a_cap)
        return u, FormationOutput(*(fo[:, j].copy() for j in range(N_FO)))


# -------------------------------------------------------------------- verification

_VERIFY_RTOL = 1e-9
_VERIFY_ATOL = 1e-9


def _close(a, b) -> bool:
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=_VERIFY_RTOL, atol=_VERIFY_ATOL,
                                                   equal_nan=True))


def _synthetic_state(cfg: FleetConfig, targets: Targets, seed: int = 12345) -> FleetState:
    """Members near their targets with perturbed pose, speed, slip, yaw rate and steering."""
    from . import fleet as fl

    rng = np.random.default_rng(seed)
    n = cfg.n
    pos = targets.p + rng.normal(0.0, 1.5, (n, 2))
    heading = np.arctan2(targets.v[:, 1], targets.v[:, 0]) + rng.normal(0.0, 0.05, n)
    speed = np.hypot(targets.v[:, 0], targets.v[:, 1]) * rng.uniform(0.0, 1.3, n)
    speed[::3] = rng.uniform(0.0, 2.5, len(speed[::3]))  # the low-speed blend
    yaw = rng.normal(0.0, 0.05, n)
    steer = rng.normal(0.0, 0.05, n)
    st = fl.initial_state(cfg, pos, heading, speed, yaw, steer, targets)
    if cfg.model == "dynamic":
        st.x[:, 4] = rng.normal(0.0, 0.01, n)
    st.theta_star[:] = st.theta_star + rng.normal(0.0, 0.1, n)
    return st


def _compare_period(ff: FastFleet, state, targets, u_ref, fo_ref, u, fo, what: str):
    ok = _close(u, u_ref)
    for j, name in enumerate(("v_ref", "omega_ref", "theta_star_dot", "v_ref_dot", "ex", "ey",
                              "heading_error")):
        ok = ok and _close(fo[:, j], getattr(fo_ref, name))
    if not ok:
        raise FastPathMismatch(f"compiled control differs from fleet.control ({what})")


def _compare_signals(sig: np.ndarray, ref: dict):
    """The compiled signals array against fleet.member_signals' dict (columns it has)."""
    for j, name in enumerate(SIGNAL_COLUMNS):
        if name in ref and not _close(sig[:, j], np.broadcast_to(ref[name], (sig.shape[0],))):
            raise FastPathMismatch(f"compiled signal {name!r} differs from fleet.member_signals")


def _verify_road(ff: FastFleet, line, slots, rigid):
    """One period and the signals, kernels against the numpy path (see from_config)."""
    from . import fleet as fl
    from ..road.leader import road_leader_state
    from .sumo_loop import _advance_vc, _targets

    cfg = ff.cfg
    n = cfg.n
    for attempt in range(2):
        try:
            # frame and projection
            s_chk = np.array([-7.0, 0.0, 0.3 * line.length, 0.7 * line.length + 0.123,
                              line.length, line.length + 11.0])
            G_line = ff.line.G
            f = line.frame(s_chk)
            fr = fast_line.frame_many(G_line, s_chk)
            if not (_close(fr[:, 0:2], f.position) and _close(fr[:, 2:4], f.tangent)
                    and _close(fr[:, 4], f.heading) and _close(fr[:, 5], f.curvature)
                    and _close(fr[:, 6], f.curvature_rate)):
                raise FastPathMismatch("FastLine.frame differs from ReferenceLine.frame")
            normal = np.c_[-f.tangent[:, 1], f.tangent[:, 0]]
            xy = f.position + np.array([3.0, -2.0, 5.5, -9.0, 1.0, 4.0])[:, None] * normal
            s_r, d_r = line.to_frenet(xy)
            s_f, d_f = to_frenet_many(G_line, _f64(xy), np.full(len(xy), np.nan))
            if not (_close(s_f, s_r) and _close(d_f, d_r)):
                raise FastPathMismatch("FastLine.to_frenet differs from ReferenceLine.to_frenet")
            # targets, control, one step, signals
            plan_road = _RoadShim(line)
            s_vc, v_vc, a_vc = 0.4 * line.length, 23.0, -0.7
            tg = _targets(plan_road, slots, rigid, ff.is_road, s_vc, v_vc, a_vc)
            T = mixed_targets_nb(G_line, ff.slots, ff.rigid, ff.is_road, s_vc, v_vc, a_vc)
            if not (_close(T[:, 0:2], tg.p) and _close(T[:, 2:4], tg.v)
                    and _close(T[:, 4:6], tg.a)):
                raise FastPathMismatch("compiled targets differ from sumo_loop._targets")
            state = _synthetic_state(cfg, tg)
            v_cap = np.full(n, np.inf)
            v_cap[::2] = 10.0
            a_cap = np.full(n, np.inf)
            a_cap[1::2] = -1.0
            u_ref, fo_ref = fl.control(cfg, state, tg, v_cap, a_cap)
            u, fo = control_nb(_f64(state.x), _f64(state.theta_star), _f64(state.speed_in),
                               ff.model_kind, ff.k, ff.k_theta, ff.C, T, v_cap, a_cap)
            _compare_period(ff, state, tg, u_ref, fo_ref, u, fo, "road")
            dt_c = 0.01
            st_ref = fl.advance(cfg, state, u_ref, fo_ref, dt_c)
            s_ref, v_ref = _advance_vc(s_vc, v_vc, a_vc, dt_c)
            st, s1, v1 = ff.step(state, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, 1)
            if not (_close(st.x, st_ref.x) and _close(st.theta_star, st_ref.theta_star)
                    and _close(st.speed_in, st_ref.speed_in) and _close([s1, v1], [s_ref, v_ref])):
                raise FastPathMismatch("compiled step differs from fleet.advance")
            vc = road_leader_state(line, s_vc, v_vc, a_vc)
            _compare_signals(ff.signals(state, s_vc, v_vc, a_vc, v_cap, a_cap),
                             fl.member_signals(cfg, state, u_ref, fo_ref, tg, vc.theta))
            return
        except FastPathMismatch:
            if attempt:
                raise
            recompile_all()  # a stale on-disk cache is the usual cause: compile afresh


class _RoadShim:
    """The one field of sim.road_setup.Road that sumo_loop._targets reads."""

    def __init__(self, line):
        self.line = line


def _verify_free(ff: FastFleet, leader, offsets):
    from . import fleet as fl
    from ..control.formation import rigid_targets

    cfg = ff.cfg
    for attempt in range(2):
        try:
            t, pose = 1.234, (10.0, -3.0, 0.3)
            vc = leader.sample(t, pose)
            tg = rigid_targets(vc, offsets)
            state = _synthetic_state(cfg, tg)
            u_ref, fo_ref = fl.control(cfg, state, tg)
            st_ref = fl.advance(cfg, state, u_ref, fo_ref, 0.01)
            pose_ref = leader.advance(t, pose, 0.01)
            st, pose1 = ff.step_free(state, t, pose, 0.01, 1)
            if not (_close(st.x, st_ref.x) and _close(st.theta_star, st_ref.theta_star)
                    and _close(st.speed_in, st_ref.speed_in) and _close(pose1, pose_ref)):
                raise FastPathMismatch("compiled free-space step differs from the numpy path")
            _compare_signals(ff.signals_free(state, t, pose),
                             fl.member_signals(cfg, state, u_ref, fo_ref, tg, vc.theta))
            return
        except FastPathMismatch:
            if attempt:
                raise
            recompile_all()


# ------------------------------------------------------------ numba cache maintenance

_DEPENDENCIES = (Path(fast_line.__file__), Path(bicycle_fast.__file__), Path(resistance.__file__),
                 Path(__file__))


def _dispatchers():
    """The compiled functions defined in road/fast_line.py and here (callees first)."""
    seen = []
    for mod in (fast_line.__name__, __name__):
        ns = vars(fast_line) if mod == fast_line.__name__ else globals()
        for obj in list(ns.values()):
            if (hasattr(obj, "py_func") and hasattr(obj, "_cache")
                    and obj.py_func.__module__ == mod and obj not in seen):
                seen.append(obj)
    return seen


_RECOMPILED = []


def recompile_all() -> None:
    """Drop the on-disk cache of this module's (and fast_line's) kernels and every compiled
    signature in this process; they compile afresh (a few seconds). Once per process: a
    mismatch that survives it is not a stale cache."""
    if _RECOMPILED:
        return
    _RECOMPILED.append(True)
    for d in _dispatchers():
        try:
            d._cache.flush()
        except Exception:  # pragma: no cover - numba internals
            pass
        d.recompile()


def _check_dependency_digest() -> None:
    """Numba keys its cache on this file only: drop it when a file whose compiled functions
    the kernels call changed since the cache was written."""
    try:
        h = hashlib.sha256()
        for p in _DEPENDENCIES:
            h.update(p.read_bytes())
        digest = h.hexdigest()
        cache_dir = Path(step_periods_nb._cache.cache_path)
        stamp = cache_dir / "fast_kernels.digest"
        old = stamp.read_text().strip() if stamp.exists() else None
        if old != digest:
            for d in _dispatchers():
                if d.py_func.__module__ == __name__:
                    d._cache.flush()
            cache_dir.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest)
    except Exception:  # pragma: no cover - read-only tree etc.: verify=True still guards
        pass


_check_dependency_digest()


def warmup() -> None:
    """Compile (or load from the cache) all kernels for the argument types the loops use."""
    from ..models.params import PASSENGER_CAR, bicycle_params, make_tires, stack
    from ..control.schedule import SPEED_GAINS_CAR, YAW_GAINS_RETUNED
    from ..road.geometry import ReferenceLine

    line = ReferenceLine.from_points(np.c_[np.linspace(0.0, 200.0, 51), np.zeros(51)])
    for model in ("dynamic", "kinematic"):
        params = stack([bicycle_params(PASSENGER_CAR, 1.0, make_tires(PASSENGER_CAR, 1.0))] * 2) \
            if model == "dynamic" else None
        cfg = FleetConfig(("a", "b"), model, params, np.array([3.0, 3.0]), np.array([2.0, 2.0]),
                          SPEED_GAINS_CAR, YAW_GAINS_RETUNED, 0.01)
        ff = FastFleet.from_config(cfg, line, np.array([[0.0, 0.0], [np.nan, np.nan]]),
                                   np.array([[np.nan, np.nan], [-10.0, 0.0]]),
                                   np.array([True, False]), verify=False)
        st = FleetState(np.zeros((2, 7 if model == "dynamic" else 3)), np.zeros(2), np.zeros(2))
        ff.step(st, 50.0, 10.0, 0.0, None, None, 0.01, 1)
        ff.signals(st, 50.0, 10.0, 0.0)
        ff.to_frenet(np.zeros((1, 2)), np.zeros(1))
        ff.kinematics(st)
