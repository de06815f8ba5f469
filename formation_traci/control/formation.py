"""Nonlinear virtual-structure formation controller, eqs (2.4)-(2.11).

Each member tracks a desired point attached to the virtual car. The desired point's
position, velocity and acceleration are computed analytically from the virtual car's
pose, v, omega and their time derivatives (no finite differences), and from the slot's
offset and its time derivatives (zero for a fixed structure; a maneuver moves the slot).

The laws are compiled scalar kernels (``*_at``), called per member by the step kernels of
sim/fleet.py; :func:`rigid_targets`, :func:`formation_control` and
:func:`initial_theta_star` are thin array wrappers (positions (n, 2), per-member (n,)).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..core.kernels import clip, kernel, maximum, wrap_angle as _wrap
from ..core.states import LeaderState, Targets  # noqa: F401 (re-exported)

VC_X, VC_Y, VC_THETA, VC_V, VC_OMEGA, VC_V_DOT, VC_OMEGA_DOT, VC_S = range(8)
"""Slots of a virtual car's row (control/reference.py VC_FIELDS: Reference.vc's last axis)."""
SLOT_DX, SLOT_DY, SLOT_DX_DOT, SLOT_DY_DOT, SLOT_DX_DDOT, SLOT_DY_DDOT = range(6)
"""Slots of a slot's row (control/reference.py SLOT_FIELDS: Reference.slots' last axis)."""

V_EPS = 0.5
"""Floor of the commanded speed in the denominators of (2.9) and of v dot [m/s] (ours)."""
K_WAIT = 10.0
"""While a member waits (its slot is behind it), theta* relaxes to its heading at this rate [1/s]."""
COS_WAIT = 0.2
"""The seed's law acts unchanged while (x~, y~) is within acos(0.2) = 78 deg of the heading;
towards 90 deg and beyond it fades linearly into waiting."""


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


class Target(NamedTuple):
    """A member's desired point in a control period (control/targets.py law_point_at): what a control
    law steers about (control/laws/__init__.py)."""

    px: float  # position x [m]
    py: float  # position y [m]
    vx: float  # velocity x [m/s]
    vy: float  # velocity y [m/s]
    ax: float  # acceleration x [m/s^2]
    ay: float  # acceleration y [m/s^2]


@kernel
def rigid_target_at(car, slot):
    """Desired point of a slot d = (dx, dy) in the virtual car's frame, eq (2.4), and its
    time derivatives: (px, py, vx, vy, ax, ay). ``car``: the virtual car's x, y [m], theta
    [rad], v [m/s], omega [rad/s], v_dot [m/s^2], omega_dot [rad/s^2] (a Reference.vc row,
    control/reference.py VC_FIELDS); ``slot``: dx, dy [m], their rates [m/s] and second
    derivatives [m/s^2] (a Reference.slots row, SLOT_FIELDS).

    p_d = p_vc + R(theta) d,
    p_d' = v t + omega R J d + R d',
    p_d'' = v' t + v omega n + omega' R J d - omega^2 R d + 2 omega R J d' + R d'',
    with t = (cos theta, sin theta), n = (-sin theta, cos theta), J = rotation by +90 deg;
    d' = d'' = 0 is the seed's rigid structure.
    """
    X, Y, th, v, om = car[VC_X], car[VC_Y], car[VC_THETA], car[VC_V], car[VC_OMEGA]
    v_dot, om_dot = car[VC_V_DOT], car[VC_OMEGA_DOT]
    dx, dy, dx_dot, dy_dot = slot[SLOT_DX], slot[SLOT_DY], slot[SLOT_DX_DOT], slot[SLOT_DY_DOT]
    dx_ddot, dy_ddot = slot[SLOT_DX_DDOT], slot[SLOT_DY_DDOT]
    c = np.cos(th)
    s = np.sin(th)
    rdx = dx * c - dy * s
    rdy = dx * s + dy * c
    rjx = -dx * s - dy * c
    rjy = dx * c - dy * s
    vo = v * om
    om2 = om ** 2
    return (X + rdx, Y + rdy,
            v * c + om * rjx + (dx_dot * c - dy_dot * s),
            v * s + om * rjy + (dx_dot * s + dy_dot * c),
            v_dot * c + vo * -s + om_dot * rjx - om2 * rdx
            + (2.0 * om * (-dx_dot * s - dy_dot * c) + (dx_ddot * c - dy_ddot * s)),
            v_dot * s + vo * c + om_dot * rjy - om2 * rdy
            + (2.0 * om * (dx_dot * c - dy_dot * s) + (dx_ddot * s + dy_ddot * c)))


@kernel
def formation_at(target, X, Y, velx, vely, heading, theta_star, k, k_theta):
    """Eqs (2.5)-(2.10) for one member with desired point ``target`` (p, p', p'':
    control/formation.py Target) and position X, Y [m], velocity velx, vely [m/s], heading
    [rad], theta* (2.11) [rad], gains k [m/s] and k_theta [1/s]: (v_ref, omega_ref, theta*
    dot, v_ref dot, ex, ey, heading error).

    e = p_d - p (2.5); (x~, y~) = p_d' + k tanh(e) (2.7); v_ref = |(x~, y~)| (2.6);
    theta* dot from the rotation of (x~, y~) (2.9); omega_ref = theta* dot + k_theta
    wrap(theta* - theta) (2.8, 2.10). V_EPS floors v_ref in the denominators. No turning
    around (ours, docs/model.md): when (x~, y~) points sideways or behind the member it
    fades into waiting (theta* relaxes to the heading at K_WAIT).
    """
    tvx, tvy, tax, tay = target.vx, target.vy, target.ax, target.ay
    ex = target.px - X
    ey = target.py - Y
    tlx = tvx + k * np.tanh(ex)
    tly = tvy + k * np.tanh(ey)
    chx = np.cosh(ex)
    chy = np.cosh(ey)
    tldx = tax + k * (1.0 / (chx * chx)) * (tvx - velx)
    tldy = tay + k * (1.0 / (chy * chy)) * (tvy - vely)
    v_ref = np.hypot(tlx, tly)
    v_safe = maximum(v_ref, V_EPS)
    tsd = (-tldx * tly + tldy * tlx) / (v_safe * v_safe)
    he = _wrap(theta_star - heading)
    omega_ref = tsd + k_theta * he
    v_ref_dot = (tlx * tldx + tly * tldy) / v_safe
    w = clip((tlx * np.cos(heading) + tly * np.sin(heading)) / v_safe / COS_WAIT, 0.0, 1.0)
    if w < 1.0:
        v_ref = w * v_ref
        omega_ref = w * omega_ref
        v_ref_dot = w * v_ref_dot
        tsd = w * tsd - (1.0 - w) * K_WAIT * np.sin(theta_star - heading)
    return (v_ref, omega_ref, tsd, v_ref_dot, ex, ey, he)


@kernel
def initial_theta_star_at(px, py, tvx, tvy, X, Y, heading, k):
    """theta*(0) = atan2(y~(0), x~(0)), eq (2.11); the heading where |(x~, y~)| < V_EPS."""
    tlx = tvx + k * np.tanh(px - X)
    tly = tvy + k * np.tanh(py - Y)
    if np.hypot(tlx, tly) < V_EPS:
        return heading
    return np.arctan2(tly, tlx)


# ------------------------------------------------------------------ array wrappers

def wrap_angle(a):
    """Wrap an angle to (-pi, pi] [rad] (kernels.wrap_angle on floats or arrays)."""
    a = np.asarray(a, dtype=float)
    return float(_wrap(float(a))) if a.ndim == 0 else _wrap(np.ascontiguousarray(a))


def rigid_targets(vc: LeaderState, offsets: np.ndarray) -> Targets:
    """Desired points of a rigid virtual structure, eq (2.4), and their derivatives
    (:func:`rigid_target_at` per member; offsets (n, 2) (d_x, d_y) [m], x forward, y left)."""
    offsets = np.asarray(offsets, dtype=float)
    car = np.array([vc.x, vc.y, vc.theta, vc.v, vc.omega, vc.v_dot, vc.omega_dot], dtype=float)
    T = np.array([rigid_target_at(car, np.array([dx, dy, 0.0, 0.0, 0.0, 0.0], dtype=float))
                  for dx, dy in offsets], dtype=float).reshape(len(offsets), 6)
    return Targets(T[:, 0:2], T[:, 2:4], T[:, 4:6])


def initial_theta_star(targets: Targets, pos: np.ndarray, heading: np.ndarray, k) -> np.ndarray:
    """theta*(0) of every member, eq (2.11) (:func:`initial_theta_star_at`)."""
    n = len(pos)
    k = np.broadcast_to(np.asarray(k, dtype=float), (n,))
    heading = np.broadcast_to(np.asarray(heading, dtype=float), (n,))
    return np.array([initial_theta_star_at(targets.p[i, 0], targets.p[i, 1], targets.v[i, 0],
                                           targets.v[i, 1], pos[i, 0], pos[i, 1], heading[i],
                                           k[i]) for i in range(n)], dtype=float)


def formation_control(targets: Targets, pos: np.ndarray, vel: np.ndarray, heading: np.ndarray,
                      theta_star: np.ndarray, k, k_theta) -> FormationOutput:
    """Eqs (2.5)-(2.10) for every member (:func:`formation_at`).

    targets: desired position/velocity/acceleration (eq 2.4 and derivatives); pos, vel (n, 2)
    member position [m] and velocity [m/s]; heading, theta_star (n,) [rad]; k [m/s],
    k_theta [1/s] float or (n,).
    """
    n = len(pos)
    k = np.broadcast_to(np.asarray(k, dtype=float), (n,))
    k_theta = np.broadcast_to(np.asarray(k_theta, dtype=float), (n,))
    out = np.array([formation_at(Target(targets.p[i, 0], targets.p[i, 1], targets.v[i, 0],
                                        targets.v[i, 1], targets.a[i, 0], targets.a[i, 1]),
                                 pos[i, 0], pos[i, 1], vel[i, 0], vel[i, 1], heading[i],
                                 theta_star[i], k[i], k_theta[i]) for i in range(n)], dtype=float)
    out = out.reshape(n, 7)
    return FormationOutput(*(out[:, j].copy() for j in range(7)))
