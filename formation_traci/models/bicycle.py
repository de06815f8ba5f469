"""Dynamic single-track (bicycle) model with Magic Formula tires, eqs (3.1)-(3.25).

State (columns of ``x``, shape (n, 7)), see :class:`S`:
    X, Y [m]   centre of gravity in the global frame (3.24)-(3.25)
    PSI [rad]  yaw angle, counter-clockwise from +X
    V [m/s]    speed of the centre of gravity, v >= 0 (3.1)
    BETA [rad] side-slip angle (3.2)
    R [rad/s]  yaw rate psi dot (3.3)
    DELTA [rad] front road-wheel steering angle, integrated from the rate input (3.38)
    A_D [m/s^2] the drive/brake demand the actuator delivers (drive_lag_s > 0; else inert, 0)
    DELTA_C [rad] the steering command the actuator follows (steer_lag_s > 0; else inert)
Input (columns of ``u``, shape (n, 2)), see :class:`U`:
    A_REF [m/s^2]  desired acceleration a_r, turned into traction force by (3.13)
    STEER_RATE [rad/s]  steering rate delta dot (3.37)

Every law is a compiled scalar kernel (``*_at``) taking one vehicle's state and row ``i`` of
the per-member parameter array ``P`` (models/params.py ``pack_params``); :func:`rhs`,
:func:`outputs` and :func:`project` are thin array wrappers over them.

With the ``resistances`` parameter on, the driving resistance F_res (rolling 3.15,
aerodynamic, grade: models/resistance.py) acts along the velocity: v dot gets -F_res / m and
(3.13) asks for m a_r + F_res, so the traction limit (3.14) and the friction circle see it
(docs/energy.md). Off (the default) is the seed's model, bit for bit.

Actuator lags (docs/model.md "Actuator dynamics"): with ``drive_lag_s`` = tau_d > 0 the traction
law (3.13) is asked for the delivered demand A_D, a_d' = (a_r - a_d) / tau_d; with
``steer_lag_s`` = tau_s > 0 the rate input drives the command, delta_c' = delta dot (3.37 with its
limits), and the wheel follows it, delta' = (delta_c - delta) / tau_s. With both 0 (the default)
the two slots have zero derivative and the rest of the row is integrated bit for bit as before.

Deviations from the seed (see docs/model.md): beta dot uses the exact single-track form
instead of (3.2); the traction limit (3.14) uses the static front-axle load (b, not a);
braking is limited by mu m g; below a few m/s the model blends into the kinematic bicycle.
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np

from ..core.kernels import clip, kernel, maximum
from .params import (_A, _AREA, _B, _BF, _BR, _CD, _CF, _CR, _DF, _DR, _DRAG, _EF, _ER, _GRADE,
                     _H, _IZZ, _LIN, _M, _MU, _RES, _RHO, _SMAX, _SRMAX, _TAU, _TAUSTOP, _VHIGH,
                     _VLOW, _DLAG, _SLAG, G, BicycleParams, pack_params)
from .resistance import aero_force, road_load, rolling_coefficient
from .tire import cornering_force


class S(IntEnum):
    """State slots of the dynamic bicycle model."""

    X = 0
    Y = 1
    PSI = 2
    V = 3
    BETA = 4
    R = 5
    DELTA = 6
    A_D = 7
    DELTA_C = 8


class U(IntEnum):
    """Input slots of the dynamic bicycle model."""

    A_REF = 0
    STEER_RATE = 1


N_STATES = len(S)
N_CORE = 7
"""The slots of (3.1)-(3.25): X .. DELTA (:func:`rhs_at`); the actuator slots follow."""


@kernel
def traction_force_max_at(v, m, a, b, h, mu):
    """Adhesion limit of the driven front axle [N], eq (3.14) with the front static load.

    F_max = mu W (b + f_rl h) / L / (1 + mu h / L). The seed writes ``a`` where the
    front-wheel-drive formula needs the CoG-to-rear-axle distance ``b`` (the front axle
    carries W b / L); see docs/model.md.
    """
    L = a + b
    return mu * (m * G) * (b + rolling_coefficient(v) * h) / L / (1.0 + mu * h / L)


@kernel
def slip_angles_at(v, beta, r, delta, a, b, v_low):
    """Front and rear tire slip angles [rad], eqs (3.7)-(3.8).

    Body velocities are x dot = v cos(beta), y dot = v sin(beta) (3.20)-(3.21). The speed is
    floored at ``v_low`` so that the angles stay finite at standstill.
    """
    vs = maximum(v, v_low)
    vx = vs * np.cos(beta)
    vy = vs * np.sin(beta)
    return np.arctan2(vy + a * r, vx) - delta, np.arctan2(vy - b * r, vx)


@kernel
def traction_from_acceleration_at(a_ref, beta, delta, fcf, fcr, m, f_res):
    """Traction force F_lf [N] that gives v dot = a_ref, eq (3.13) (unclipped), against the
    driving resistance f_res [N] (0: the seed's model, which drives against none)."""
    num = m * a_ref - fcf * (np.cos(delta) * np.sin(beta) - np.sin(delta) * np.cos(beta)) \
        - fcr * np.sin(beta)
    if f_res != 0.0:
        num = num + f_res
    den = np.cos(delta) * np.cos(beta) + np.sin(delta) * np.sin(beta)
    return num / den


@kernel
def resistance_at(v, P, i):
    """Driving resistance of vehicle i along its velocity [N] (models/resistance.py
    road_load with its drag ratio and grade), 0 with resistances off (the seed's model)."""
    if P[i, _RES] == 0.0:
        return 0.0
    return road_load(v, P[i, _M], P[i, _CD], P[i, _AREA], P[i, _RHO], P[i, _DRAG], P[i, _GRADE])


@kernel
def forces_at(v, beta, r, delta, a_ref, P, i):
    """Slip angles, cornering forces (3.9-3.12), the clipped traction force (3.13-3.15) and
    its upper limit of vehicle i: (alpha_f, alpha_r, F_cf, F_cr, F_lf, F_max, F_res).

    With resistances on, (3.13) asks for m a_ref + F_res (F_res: :func:`resistance_at`)."""
    m = P[i, _M]
    alpha_f, alpha_r = slip_angles_at(v, beta, r, delta, P[i, _A], P[i, _B], P[i, _VLOW])
    lin = P[i, _LIN] != 0.0
    fcf = cornering_force(alpha_f, P[i, _BF], P[i, _CF], P[i, _DF], P[i, _EF], lin)
    fcr = cornering_force(alpha_r, P[i, _BR], P[i, _CR], P[i, _DR], P[i, _ER], lin)
    f_max = traction_force_max_at(v, m, P[i, _A], P[i, _B], P[i, _H], P[i, _MU])
    f_res = resistance_at(v, P, i)
    f_lf = clip(traction_from_acceleration_at(a_ref, beta, delta, fcf, fcr, m, f_res),
                -(P[i, _MU] * m * G), f_max)
    return alpha_f, alpha_r, fcf, fcr, f_lf, f_max, f_res


@kernel
def steering_rate_at(delta, rate_in, steer_max, steer_rate_max):
    """Applied steering rate [rad/s]: the input clipped to the rate limit and zeroed when it
    would push the wheel past the angle limit (3.37-3.38 with actuator limits)."""
    rate = clip(rate_in, -steer_rate_max, steer_rate_max)
    if (delta >= steer_max and rate > 0.0) or (delta <= -steer_max and rate < 0.0):
        return 0.0
    return rate


@kernel
def kinematic_bicycle_at(v, beta, r, delta, v_dot, ddelta, a, b, tau):
    """Low-speed part: beta and r relax with time constant tau to the kinematic bicycle's
    beta_k = atan(b tan(delta) / L), r_k = v cos(beta_k) tan(delta) / L, plus their
    feed-forward rates. Returns (beta dot, r dot)."""
    L = a + b
    td = np.tan(delta)
    sec2 = 1.0 + td * td
    k = b * td / L
    beta_k = np.arctan(k)
    dbeta_k = (b / L) * sec2 / (1.0 + k * k)
    cbk = np.cos(beta_k)
    r_k = v * cbk * td / L
    dr_k_dd = v / L * (cbk * sec2 - np.sin(beta_k) * dbeta_k * td)
    beta_dot = (beta_k - beta) / tau + dbeta_k * ddelta
    r_dot = (r_k - r) / tau + cbk * td / L * v_dot + dr_k_dd * ddelta
    return beta_dot, r_dot


@kernel
def rhs_at(psi, v, beta, r, delta, a_ref, rate_in, P, i):
    """Time derivative of vehicle i's state (X, Y, psi, v, beta, r, delta dot) under the
    steering-rate input ``rate_in`` (the applied rate: :func:`steering_rate_at`); see
    :func:`rhs_applied_at`."""
    return rhs_applied_at(psi, v, beta, r, delta, a_ref,
                          steering_rate_at(delta, rate_in, P[i, _SMAX], P[i, _SRMAX]), P, i)


@kernel
def rhs_applied_at(psi, v, beta, r, delta, a_ref, ddelta, P, i):
    """Time derivative of vehicle i's state (X, Y, psi, v, beta, r, delta dot).

    Dynamic part (weight w = 1 above v_high):
        v dot    = [F_x cos(beta) + F_y sin(beta)] / m                    (3.1)
        beta dot = [F_y cos(beta) - F_x sin(beta)] / (m v) - psi dot       (exact form of 3.2)
        psi ddot = [(F_lf sin(delta) + F_cf cos(delta)) a - F_cr b] / Izz  (3.3)
    with F_x = F_lf cos(delta) - F_cf sin(delta), F_y = F_lf sin(delta) + F_cf cos(delta) + F_cr;
    with resistances on, v dot gets -F_res / m (F_lf of :func:`forces_at` includes F_res).
    Kinematic part (w = 0 below v_low): :func:`kinematic_bicycle_at`; C1 smoothstep between.
    Position (3.22)-(3.23): X dot = v cos(psi + beta), Y dot = v sin(psi + beta). Near
    standstill braking is capped at v / tau_stop (an exponential stop, no reversing).
    """
    m = P[i, _M]
    a = P[i, _A]
    b = P[i, _B]
    _, _, fcf, fcr, f_lf, f_max, f_res = forces_at(v, beta, r, delta, a_ref, P, i)
    res_on = P[i, _RES] != 0.0
    sb = np.sin(beta)
    cb = np.cos(beta)
    sd = np.sin(delta)
    cd = np.cos(delta)
    fx = f_lf * cd - fcf * sd
    fy = f_lf * sd + fcf * cd + fcr
    v_dot_dyn = (fx * cb + fy * sb) / m
    if res_on:
        v_dot_dyn = v_dot_dyn - f_res / m
    beta_dot_dyn = (fy * cb - fx * sb) / (m * maximum(v, P[i, _VLOW])) - r
    r_dot_dyn = ((f_lf * sd + fcf * cd) * a - fcr * b) / P[i, _IZZ]
    if res_on:  # the traction m a_r + F_res is clipped, the resistance always acts
        v_dot_kin = clip(a_ref + f_res / m, -(P[i, _MU] * m * G) / m, f_max / m) - f_res / m
    else:
        v_dot_kin = clip(a_ref, -(P[i, _MU] * m * G) / m, f_max / m)
    beta_dot_kin, r_dot_kin = kinematic_bicycle_at(v, beta, r, delta, v_dot_kin, ddelta, a, b,
                                                   P[i, _TAU])
    s = clip((v - P[i, _VLOW]) / (P[i, _VHIGH] - P[i, _VLOW]), 0.0, 1.0)
    w = s * s * (3.0 - 2.0 * s)
    v_dot = w * v_dot_dyn + (1.0 - w) * v_dot_kin
    v_dot = maximum(v_dot, -maximum(v, 0.0) / P[i, _TAUSTOP])
    course = psi + beta
    return (v * np.cos(course), v * np.sin(course), r, v_dot,
            w * beta_dot_dyn + (1.0 - w) * beta_dot_kin, w * r_dot_dyn + (1.0 - w) * r_dot_kin,
            ddelta)


@kernel
def project_at(v, delta, steer_max):
    """State constraints after an integration step: v >= 0, |delta| <= steer_max."""
    return maximum(v, 0.0), clip(delta, -steer_max, steer_max)


@kernel
def outputs_at(psi, v, beta, r, delta, a_ref, rate_in, P, i):
    """Recorded signals of vehicle i: (a_lon, a_lat, slip_front, slip_rear, traction_force,
    traction_force_max, friction_usage, steer_rate, power, drag_force, drag_ratio).

    Accelerations are those of the centre of gravity in the body frame, from the kinematics
    of the state derivative: a_lon = v dot cos(beta) - v sin(beta)(beta dot + r),
    a_lat = v dot sin(beta) + v cos(beta)(beta dot + r); at steady state a_lat = v r (3.6).
    ``power`` [W]: traction power at the front wheels, F_lf times the front axle's speed along
    the wheel, v cos(beta) cos(delta) + (v sin(beta) + a r) sin(delta) (= F_lf v driving
    straight); ``drag_force`` [N] and ``drag_ratio`` [-]: NaN with resistances off.
    """
    return outputs_applied_at(psi, v, beta, r, delta, a_ref,
                              steering_rate_at(delta, rate_in, P[i, _SMAX], P[i, _SRMAX]), P, i)


@kernel
def outputs_applied_at(psi, v, beta, r, delta, a_ref, ddelta, P, i):
    """:func:`outputs_at` with the applied wheel steering rate ``ddelta`` [rad/s]."""
    alpha_f, alpha_r, _, _, f_lf, f_max, _ = forces_at(v, beta, r, delta, a_ref, P, i)
    d = rhs_applied_at(psi, v, beta, r, delta, a_ref, ddelta, P, i)
    a_lon, a_lat = body_accelerations(v, beta, r, d[3], d[4])
    usage = np.hypot(a_lon, a_lat) / (P[i, _MU] * G)
    power = f_lf * (v * np.cos(beta) * np.cos(delta)
                    + (v * np.sin(beta) + P[i, _A] * r) * np.sin(delta))
    drag, ratio = np.nan, np.nan
    if P[i, _RES] != 0.0:
        ratio = P[i, _DRAG]
        drag = aero_force(v, P[i, _CD], P[i, _AREA], P[i, _RHO], ratio)
    return a_lon, a_lat, alpha_f, alpha_r, f_lf, f_max, usage, d[6], power, drag, ratio


@kernel
def body_accelerations(v, beta, r, v_dot, beta_dot):
    """Accelerations of the centre of gravity in the body frame [m/s^2], (a_lon, a_lat), of a
    state with speed v [m/s], side slip beta [rad] and yaw rate r [rad/s] whose speed and
    side slip change at v_dot [m/s^2] and beta_dot [rad/s] (:func:`outputs_applied_at`)."""
    course_rate = beta_dot + r
    return (v_dot * np.cos(beta) - v * np.sin(beta) * course_rate,
            v_dot * np.sin(beta) + v * np.cos(beta) * course_rate)


OUTPUT_NAMES = ("a_lon", "a_lat", "slip_front", "slip_rear", "traction_force",
                "traction_force_max", "friction_usage", "steer_rate", "power", "drag_force",
                "drag_ratio")
"""The signals :func:`outputs_at` returns, in its order."""
N_OUTPUTS = len(OUTPUT_NAMES)


# ------------------------------------------------------------------ array wrappers

@kernel
def _rows(x, u, P, what):
    n = x.shape[0]
    out = np.empty((n, N_OUTPUTS if what == 1 else 7))
    for i in range(n):
        if what == 1:
            res = outputs_at(x[i, 2], x[i, 3], x[i, 4], x[i, 5], x[i, 6], u[i, 0], u[i, 1], P, i)
            for j in range(N_OUTPUTS):
                out[i, j] = res[j]
        else:
            res7 = rhs_at(x[i, 2], x[i, 3], x[i, 4], x[i, 5], x[i, 6], u[i, 0], u[i, 1], P, i)
            for j in range(7):
                out[i, j] = res7[j]
    return out


def _arrays(x, u, p: BicycleParams):
    x = np.ascontiguousarray(x, dtype=np.float64)
    u = np.ascontiguousarray(np.broadcast_to(u, (len(x), 2)), dtype=np.float64)
    return x, u, pack_params(p, len(x))


def rhs(x, u, p: BicycleParams) -> np.ndarray:
    """Time derivative of the states x (n, 7) under inputs u (n, 2): :func:`rhs_at` per row."""
    return _rows(*_arrays(x, u, p), 0)


def outputs(x, u, p: BicycleParams) -> dict[str, np.ndarray]:
    """Recorded signals for state x under input u (all shape (n,)): :func:`outputs_at`."""
    o = _rows(*_arrays(x, u, p), 1)
    return {name: o[:, j].copy() for j, name in enumerate(OUTPUT_NAMES)}


def forces(x, u, p: BicycleParams):
    """(alpha_f, alpha_r, F_cf, F_cr, F_lf, F_max) of every row of x under u, each (n,)
    (:func:`forces_at`)."""
    x, u, P = _arrays(x, u, p)
    res = [forces_at(x[i, 3], x[i, 4], x[i, 5], x[i, 6], u[i, 0], P, i)[:6]
           for i in range(len(x))]
    return tuple(np.array(res, dtype=float).reshape(len(x), 6).T)


def steering_rate(x, u, p: BicycleParams) -> np.ndarray:
    """Applied steering rate of every row [rad/s] (:func:`steering_rate_at`)."""
    x, u, P = _arrays(x, u, p)
    return np.array([steering_rate_at(x[i, 6], u[i, 1], P[i, _SMAX], P[i, _SRMAX])
                     for i in range(len(x))], dtype=float)


def traction_force_max(v, p: BicycleParams):
    """:func:`traction_force_max_at` for parameters p (v [m/s], float or array)."""
    return traction_force_max_at(v, p.m, p.a, p.b, p.h, p.mu)


def project(x, p: BicycleParams):
    """Enforce the state constraints after an integration step (:func:`project_at`)."""
    x[:, S.V] = np.maximum(x[:, S.V], 0.0)
    x[:, S.DELTA] = np.clip(x[:, S.DELTA], -p.steer_max, p.steer_max)
    return x


# ------------------------------------------------ the model over a named state row (integrator)

@kernel
def actuated_at(s, u0, u1, P, i):
    """What the actuators deliver to the chassis for inputs (a_r, steering rate) at state row
    ``s``: (a_ref [m/s^2], applied wheel steering rate [rad/s], a_d dot, delta_c dot)."""
    td = P[i, _DLAG]
    ts = P[i, _SLAG]
    a_in = u0
    a_dot = 0.0
    if td > 0.0:
        a_in = s[S.A_D]
        a_dot = (u0 - s[S.A_D]) / td
    if ts > 0.0:
        c_dot = steering_rate_at(s[S.DELTA_C], u1, P[i, _SMAX], P[i, _SRMAX])
        return a_in, (s[S.DELTA_C] - s[S.DELTA]) / ts, a_dot, c_dot
    return a_in, steering_rate_at(s[S.DELTA], u1, P[i, _SMAX], P[i, _SRMAX]), a_dot, 0.0


@kernel
def rhs_into(s, u0, u1, P, i, out):
    """:func:`rhs_at` of the state row ``s`` (slots :class:`S`) under (a_ref, steering rate)
    into ``out``, through the actuators (:func:`actuated_at`): the form models/integrator.py
    integrates. A row of the N_CORE slots alone is the model without actuator slots."""
    if P[i, _DLAG] == 0.0 and P[i, _SLAG] == 0.0:
        d = rhs_at(s[S.PSI], s[S.V], s[S.BETA], s[S.R], s[S.DELTA], u0, u1, P, i)
        for q in range(N_CORE):
            out[q] = d[q]
        for q in range(N_CORE, s.shape[0]):
            out[q] = 0.0
        return
    a_in, rate, a_dot, c_dot = actuated_at(s, u0, u1, P, i)
    d = rhs_applied_at(s[S.PSI], s[S.V], s[S.BETA], s[S.R], s[S.DELTA], a_in, rate, P, i)
    for q in range(N_CORE):
        out[q] = d[q]
    out[S.A_D] = a_dot
    out[S.DELTA_C] = c_dot


@kernel
def outputs_of(s, u0, u1, P, i):
    """:func:`outputs_at` of state row ``s`` under (a_r, steering rate) through the actuators
    (the recorded signals; with no lag exactly :func:`outputs_at` of the inputs)."""
    if P[i, _DLAG] == 0.0 and P[i, _SLAG] == 0.0:
        return outputs_at(s[S.PSI], s[S.V], s[S.BETA], s[S.R], s[S.DELTA], u0, u1, P, i)
    a_in, rate, _, _ = actuated_at(s, u0, u1, P, i)
    return outputs_applied_at(s[S.PSI], s[S.V], s[S.BETA], s[S.R], s[S.DELTA], a_in, rate, P, i)


@kernel
def constrain(s, P, i):
    """:func:`project_at` on the state row ``s`` after an integration step (and the steering
    command's angle limit)."""
    s[S.V], s[S.DELTA] = project_at(s[S.V], s[S.DELTA], P[i, _SMAX])
    if P[i, _SLAG] > 0.0:
        s[S.DELTA_C] = clip(s[S.DELTA_C], -P[i, _SMAX], P[i, _SMAX])
