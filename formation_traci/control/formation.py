"""Nonlinear virtual-structure formation controller, eqs (2.4)-(2.11).

Each member tracks a desired point attached to the virtual car. The desired point's
position, velocity and acceleration are computed analytically from the virtual car's
pose, v, omega and their time derivatives (no finite differences). All arrays broadcast
over members: positions have shape (n, 2), scalars per member shape (n,).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

V_EPS = 0.5
"""Floor of the commanded speed in the denominators of (2.9) and of v dot [m/s] (ours)."""
K_WAIT = 10.0
"""While a member waits (its slot is behind it), theta* relaxes to its heading at this rate [1/s]."""
COS_WAIT = 0.2
"""The seed's law acts unchanged while (x~, y~) is within acos(0.2) = 78 deg of the heading;
towards 90 deg and beyond it fades linearly into waiting."""


@dataclass(frozen=True, slots=True)
class LeaderState:
    """Virtual car kinematics at one instant (eq 2.3) and the rates the controller needs."""

    x: float  # [m]
    y: float  # [m]
    theta: float  # heading [rad], counter-clockwise from +x
    v: float  # [m/s]
    omega: float  # [rad/s]
    v_dot: float  # [m/s^2]
    omega_dot: float  # [rad/s^2]


@dataclass(frozen=True, slots=True)
class Targets:
    """Desired position, velocity and acceleration of every member, shape (n, 2) each."""

    p: np.ndarray  # [m]
    v: np.ndarray  # [m/s]
    a: np.ndarray  # [m/s^2]


def rigid_targets(vc: LeaderState, offsets: np.ndarray) -> Targets:
    """Desired points of a rigid virtual structure, eq (2.4), and their derivatives.

    p_d = p_vc + R(theta) d,
    p_d' = v t + omega R(theta) J d,
    p_d'' = v' t + v omega n + omega' R(theta) J d - omega^2 R(theta) d,
    with t = (cos theta, sin theta), n = (-sin theta, cos theta), J = rotation by +90 deg.

    Parameters
    ----------
    offsets : ndarray, shape (n, 2)
        (d_x, d_y) of each member in the virtual car frame [m] (x forward, y left).
    """
    c, s = np.cos(vc.theta), np.sin(vc.theta)
    dx, dy = offsets[:, 0], offsets[:, 1]
    rd = np.stack([dx * c - dy * s, dx * s + dy * c], axis=1)  # R d
    rjd = np.stack([-dx * s - dy * c, dx * c - dy * s], axis=1)  # R J d
    t = np.array([c, s])
    nrm = np.array([-s, c])
    p = np.array([vc.x, vc.y]) + rd
    v = vc.v * t + vc.omega * rjd
    a = vc.v_dot * t + vc.v * vc.omega * nrm + vc.omega_dot * rjd - vc.omega ** 2 * rd
    return Targets(p, v, a)


@dataclass(frozen=True, slots=True)
class FormationOutput:
    """References and intermediate signals of one controller evaluation (all shape (n,))."""

    v_ref: np.ndarray  # (2.6) [m/s]
    omega_ref: np.ndarray  # (2.8) [rad/s]
    theta_star_dot: np.ndarray  # (2.9) [rad/s]
    v_ref_dot: np.ndarray  # time derivative of (2.6) [m/s^2]
    ex: np.ndarray  # (2.5) [m]
    ey: np.ndarray  # (2.5) [m]
    heading_error: np.ndarray  # (2.10) [rad], wrapped to (-pi, pi]


def _tilde(targets: Targets, pos: np.ndarray, k):
    """x~, y~ of eq (2.7), shape (n, 2), and the error e (2.5)."""
    e = targets.p - pos
    return targets.v + k[:, None] * np.tanh(e), e


def initial_theta_star(targets: Targets, pos: np.ndarray, heading: np.ndarray, k) -> np.ndarray:
    """theta*(0) = atan2(y~(0), x~(0)), eq (2.11); the member's heading where |(x~, y~)| < V_EPS."""
    tl, _ = _tilde(targets, pos, np.asarray(k, dtype=float) * np.ones(len(pos)))
    th = np.arctan2(tl[:, 1], tl[:, 0])
    return np.where(np.hypot(tl[:, 0], tl[:, 1]) < V_EPS, heading, th)


def wrap_angle(a):
    """Wrap an angle to (-pi, pi] [rad]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def formation_control(targets: Targets, pos: np.ndarray, vel: np.ndarray, heading: np.ndarray,
                      theta_star: np.ndarray, k, k_theta) -> FormationOutput:
    """Evaluate eqs (2.5)-(2.10) for every member.

    Parameters
    ----------
    targets : Targets
        Desired position/velocity/acceleration (eq 2.4 and derivatives).
    pos, vel : ndarray, shape (n, 2)
        Member position [m] and velocity [m/s] in the global frame (e dot = p_d' - vel).
    heading : ndarray, shape (n,)
        Member heading theta_i [rad].
    theta_star : ndarray, shape (n,)
        Integrated desired heading, eq (2.11) [rad].
    k, k_theta : float or ndarray, shape (n,)
        Gains of (2.7) [m/s] and (2.8) [1/s].
    """
    n = len(pos)
    k = np.broadcast_to(np.asarray(k, dtype=float), (n,))
    k_theta = np.broadcast_to(np.asarray(k_theta, dtype=float), (n,))
    tl, e = _tilde(targets, pos, k)
    e_dot = targets.v - vel
    sech2 = 1.0 / np.cosh(e) ** 2
    tl_dot = targets.a + k[:, None] * sech2 * e_dot  # d/dt of (x~, y~)
    v_ref = np.hypot(tl[:, 0], tl[:, 1])  # (2.6)
    v_safe = np.maximum(v_ref, V_EPS)
    theta_star_dot = (-tl_dot[:, 0] * tl[:, 1] + tl_dot[:, 1] * tl[:, 0]) / (v_safe * v_safe)  # (2.9)
    heading_error = wrap_angle(theta_star - heading)  # (2.10)
    omega_ref = theta_star_dot + k_theta * heading_error  # (2.8)
    v_ref_dot = (tl[:, 0] * tl_dot[:, 0] + tl[:, 1] * tl_dot[:, 1]) / v_safe
    # no turning around (ours, docs/model.md): when (x~, y~) points sideways or behind the
    # member, e.g. it stopped just past a stopped slot, it waits instead of driving a U-turn
    cos_dir = (tl[:, 0] * np.cos(heading) + tl[:, 1] * np.sin(heading)) / v_safe
    w = np.clip(cos_dir / COS_WAIT, 0.0, 1.0)
    if np.any(w < 1.0):
        v_ref = w * v_ref
        omega_ref = w * omega_ref
        v_ref_dot = w * v_ref_dot
        # smooth relaxation towards the heading (no jump where theta* - heading = +-pi)
        theta_star_dot = w * theta_star_dot - (1.0 - w) * K_WAIT * np.sin(theta_star - heading)
    return FormationOutput(v_ref, omega_ref, theta_star_dot, v_ref_dot, e[:, 0], e[:, 1],
                           heading_error)
