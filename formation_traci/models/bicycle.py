"""Dynamic single-track (bicycle) model with Magic Formula tires, eqs (3.1)-(3.25).

State (columns of ``x``, shape (n, 7)), see :class:`S`:
    X, Y [m]   centre of gravity in the global frame (3.24)-(3.25)
    PSI [rad]  yaw angle, counter-clockwise from +X
    V [m/s]    speed of the centre of gravity, v >= 0 (3.1)
    BETA [rad] side-slip angle (3.2)
    R [rad/s]  yaw rate psi dot (3.3)
    DELTA [rad] front road-wheel steering angle, integrated from the rate input (3.38)
Input (columns of ``u``, shape (n, 2)), see :class:`U`:
    A_REF [m/s^2]  desired acceleration a_r, turned into traction force by (3.13)
    STEER_RATE [rad/s]  steering rate delta dot (3.37)

Deviations from the seed (see docs/model.md): beta dot uses the exact single-track form
instead of (3.2); the traction limit (3.14) uses the static front-axle load (b, not a);
braking is limited by mu m g; below a few m/s the model blends into the kinematic bicycle.
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np

from .params import G, BicycleParams
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


class U(IntEnum):
    """Input slots of the dynamic bicycle model."""

    A_REF = 0
    STEER_RATE = 1


N_STATES = len(S)


def rolling_resistance(v):
    """Coefficient of rolling resistance f_rl = 0.01 (1 + v / 40.8) [-], eq (3.15); v in m/s."""
    return rolling_coefficient(v)


def resistance_force(v, p: BicycleParams):
    """Driving resistance along the velocity [N] (models/resistance.py road_load), or None
    when ``p.resistances`` is off (the seed's model)."""
    if not p.resistances:
        return None
    shape = np.shape(v)
    return road_load(np.asarray(v, dtype=float), *(np.broadcast_to(np.asarray(q, dtype=float), shape)
                                                  for q in (p.m, p.c_d, p.frontal_area, p.rho_air,
                                                            p.drag_ratio, p.grade)))


def traction_force_max(v, p: BicycleParams):
    """Adhesion limit of the driven front axle [N], eq (3.14) with the front static load.

    F_max = mu W (b + f_rl h) / L / (1 + mu h / L). The seed writes ``a`` where the
    front-wheel-drive formula needs the CoG-to-rear-axle distance ``b`` (the front axle
    carries W b / L); see docs/model.md.
    """
    L = p.a + p.b
    w = p.m * G
    return p.mu * w * (p.b + rolling_resistance(v) * p.h) / L / (1.0 + p.mu * p.h / L)


def braking_force_max(p: BicycleParams):
    """Largest braking force [N]: mu m g (all four wheels, ideal brake balance; ours)."""
    return p.mu * p.m * G


def slip_angles(v, beta, r, delta, p: BicycleParams):
    """Front and rear tire slip angles [rad], eqs (3.7)-(3.8).

    Body velocities are x dot = v cos(beta), y dot = v sin(beta) (3.20)-(3.21). The speed
    is floored at ``p.v_low`` so that the angles stay finite at standstill (the tire forces
    are not used there, see :func:`rhs`).
    """
    vs = np.maximum(v, p.v_low)
    vx = vs * np.cos(beta)
    vy = vs * np.sin(beta)
    alpha_f = np.arctan2(vy + p.a * r, vx) - delta
    alpha_r = np.arctan2(vy - p.b * r, vx)
    return alpha_f, alpha_r


def tire_forces(alpha_f, alpha_r, p: BicycleParams):
    """Front and rear cornering forces F_cf, F_cr [N], eqs (3.9)-(3.10) or (3.12)."""
    fcf = cornering_force(alpha_f, p.Bf, p.Cf, p.Df, p.Ef, p.linear_tire)
    fcr = cornering_force(alpha_r, p.Br, p.Cr, p.Dr, p.Er, p.linear_tire)
    return fcf, fcr


def traction_from_acceleration(a_ref, beta, delta, fcf, fcr, p: BicycleParams, f_res=None):
    """Traction force F_lf [N] that gives v dot = a_ref, eq (3.13) (unclipped); with the
    driving resistance ``f_res`` [N] (None: the seed's model without it) added to m a_ref."""
    num = p.m * a_ref - fcf * (np.cos(delta) * np.sin(beta) - np.sin(delta) * np.cos(beta)) \
        - fcr * np.sin(beta)
    if f_res is not None:
        num = num + f_res
    den = np.cos(delta) * np.cos(beta) + np.sin(delta) * np.sin(beta)
    return num / den


def _blend_weight(v, p: BicycleParams):
    """0 below v_low (kinematic), 1 above v_high (dynamic), C1 smoothstep between."""
    s = np.clip((v - p.v_low) / (p.v_high - p.v_low), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _forces(x, u, p: BicycleParams):
    """Slip angles, cornering forces and the clipped traction force for state x, input u."""
    return _loads(x, u, p)[:6]


def _loads(x, u, p: BicycleParams):
    """:func:`_forces` plus the driving resistance (None without resistances)."""
    v, beta, r, delta = x[:, S.V], x[:, S.BETA], x[:, S.R], x[:, S.DELTA]
    alpha_f, alpha_r = slip_angles(v, beta, r, delta, p)
    fcf, fcr = tire_forces(alpha_f, alpha_r, p)
    f_max = traction_force_max(v, p)
    f_res = resistance_force(v, p)
    f_lf = traction_from_acceleration(u[:, U.A_REF], beta, delta, fcf, fcr, p, f_res)
    f_lf = np.clip(f_lf, -braking_force_max(p), f_max)
    return alpha_f, alpha_r, fcf, fcr, f_lf, f_max, f_res


def steering_rate(x, u, p: BicycleParams):
    """Applied steering rate [rad/s]: the input clipped to the rate limit and zeroed when
    it would push the wheel past the angle limit (3.37-3.38 with actuator limits)."""
    rate = np.clip(u[:, U.STEER_RATE], -p.steer_rate_max, p.steer_rate_max)
    delta = x[:, S.DELTA]
    at_limit = ((delta >= p.steer_max) & (rate > 0)) | ((delta <= -p.steer_max) & (rate < 0))
    return np.where(at_limit, 0.0, rate)


def rhs(x, u, p: BicycleParams):
    """Time derivative of the dynamic bicycle state, shape (n, 7).

    Dynamic part (weight w = 1 above ``p.v_high``):
        v dot    = [F_x cos(beta) + F_y sin(beta)] / m                    (3.1)
        beta dot = [F_y cos(beta) - F_x sin(beta)] / (m v) - psi dot       (exact form of 3.2)
        psi ddot = [(F_lf sin(delta) + F_cf cos(delta)) a - F_cr b] / Izz  (3.3)
    with F_x = F_lf cos(delta) - F_cf sin(delta), F_y = F_lf sin(delta) + F_cf cos(delta) + F_cr
    and F_lf from (3.13) clipped to [-mu m g, F_max(v)] (3.14-3.15). With ``p.resistances``
    the driving resistance F_res (models/resistance.py) acts along the velocity: v dot gets
    -F_res / m and (3.13) asks for m a_r + F_res (docs/energy.md).
    Kinematic part (w = 0 below ``p.v_low``): beta and psi dot relax with time constant
    ``p.tau`` to the kinematic bicycle values beta_k = atan(b tan(delta) / L),
    r_k = v cos(beta_k) tan(delta) / L, plus their feed-forward rates.
    Position (3.22)-(3.23): X dot = v cos(psi + beta), Y dot = v sin(psi + beta).
    """
    psi, v, beta, r, delta = (x[:, S.PSI], x[:, S.V], x[:, S.BETA], x[:, S.R], x[:, S.DELTA])
    _, _, fcf, fcr, f_lf, f_max, f_res = _loads(x, u, p)
    sd, cd, sb, cb = np.sin(delta), np.cos(delta), np.sin(beta), np.cos(beta)
    fx = f_lf * cd - fcf * sd
    fy = f_lf * sd + fcf * cd + fcr
    vs = np.maximum(v, p.v_low)

    v_dot_dyn = (fx * cb + fy * sb) / p.m
    if f_res is not None:
        v_dot_dyn = v_dot_dyn - f_res / p.m
    beta_dot_dyn = (fy * cb - fx * sb) / (p.m * vs) - r
    r_dot_dyn = ((f_lf * sd + fcf * cd) * p.a - fcr * p.b) / p.Izz

    ddelta = steering_rate(x, u, p)
    L = p.a + p.b
    td = np.tan(delta)
    sec2 = 1.0 + td * td
    k = p.b * td / L
    beta_k = np.arctan(k)
    dbeta_k = (p.b / L) * sec2 / (1.0 + k * k)
    if f_res is None:
        v_dot_kin = np.clip(u[:, U.A_REF], -braking_force_max(p) / p.m, f_max / p.m)
    else:  # the traction m a_r + F_res is clipped, the resistance always acts
        v_dot_kin = np.clip(u[:, U.A_REF] + f_res / p.m, -braking_force_max(p) / p.m,
                            f_max / p.m) - f_res / p.m
    r_k = v * np.cos(beta_k) * td / L
    dr_k_dv = np.cos(beta_k) * td / L
    dr_k_dd = v / L * (np.cos(beta_k) * sec2 - np.sin(beta_k) * dbeta_k * td)
    beta_dot_kin = (beta_k - beta) / p.tau + dbeta_k * ddelta
    r_dot_kin = (r_k - r) / p.tau + dr_k_dv * v_dot_kin + dr_k_dd * ddelta

    w = _blend_weight(v, p)
    v_dot = w * v_dot_dyn + (1.0 - w) * v_dot_kin
    # near standstill braking is capped at v / tau_stop: an exponential stop, no reversing
    v_dot = np.maximum(v_dot, -np.maximum(v, 0.0) / p.tau_stop)

    dx = np.empty_like(x)
    course = psi + beta
    dx[:, S.X] = v * np.cos(course)
    dx[:, S.Y] = v * np.sin(course)
    dx[:, S.PSI] = r
    dx[:, S.V] = v_dot
    dx[:, S.BETA] = w * beta_dot_dyn + (1.0 - w) * beta_dot_kin
    dx[:, S.R] = w * r_dot_dyn + (1.0 - w) * r_dot_kin
    dx[:, S.DELTA] = ddelta
    return dx


def project(x, p: BicycleParams):
    """Enforce the state constraints after an integration step: v >= 0, |delta| <= limit."""
    x[:, S.V] = np.maximum(x[:, S.V], 0.0)
    x[:, S.DELTA] = np.clip(x[:, S.DELTA], -p.steer_max, p.steer_max)
    return x


def outputs(x, u, p: BicycleParams) -> dict[str, np.ndarray]:
    """Recorded signals for state x under input u (all shape (n,)).

    Accelerations are those of the centre of gravity in the body frame, from the
    kinematics of the state derivative: a_lon = v dot cos(beta) - v sin(beta)(beta dot + r),
    a_lat = v dot sin(beta) + v cos(beta)(beta dot + r); at steady state a_lat = v r (3.6).
    """
    alpha_f, alpha_r, _, _, f_lf, f_max = _forces(x, u, p)
    dx = rhs(x, u, p)
    v, beta = x[:, S.V], x[:, S.BETA]
    delta = x[:, S.DELTA]
    course_rate = dx[:, S.BETA] + x[:, S.R]
    a_lon = dx[:, S.V] * np.cos(beta) - v * np.sin(beta) * course_rate
    a_lat = dx[:, S.V] * np.sin(beta) + v * np.cos(beta) * course_rate
    return {
        "a_lon": a_lon,
        "a_lat": a_lat,
        "slip_front": alpha_f,
        "slip_rear": alpha_r,
        "traction_force": f_lf,
        "traction_force_max": np.broadcast_to(f_max, v.shape).astype(float),
        "friction_usage": np.hypot(a_lon, a_lat) / (p.mu * G),
        "steer_rate": dx[:, S.DELTA],
        **energy_outputs(v, beta, x[:, S.R], delta, f_lf, p),
    }


def energy_outputs(v, beta, r, delta, f_lf, p: BicycleParams) -> dict[str, np.ndarray]:
    """``power`` [W]: traction power at the front wheels, F_lf times the front axle's speed
    along the wheel, v cos(beta) cos(delta) + (v sin(beta) + a r) sin(delta) (= F_lf v when
    driving straight); ``drag_force`` [N] and ``drag_ratio`` [-] (NaN without resistances)."""
    power = f_lf * (v * np.cos(beta) * np.cos(delta) + (v * np.sin(beta) + p.a * r) * np.sin(delta))
    if not p.resistances:
        nan = np.full(np.shape(v), np.nan)
        return {"power": power, "drag_force": nan, "drag_ratio": nan.copy()}
    ratio = np.broadcast_to(np.asarray(p.drag_ratio, dtype=float), np.shape(v))
    drag = aero_force(np.asarray(v, dtype=float), *(np.broadcast_to(np.asarray(q, dtype=float), np.shape(v))
                                                   for q in (p.c_d, p.frontal_area, p.rho_air)), ratio)
    return {"power": power, "drag_force": drag, "drag_ratio": ratio.astype(float)}
