"""Linearised lateral dynamics of the bicycle model, eqs (3.26)-(3.31).

Linearised about v = v_lin, beta = 0, psi dot = 0, delta = 0, a_r = 0 with the linear tire
(3.12) on both axles. The seed's (3.28)-(3.30) print the yaw-damping term without the
1/v that its numbers in (3.31) keep, and print B's entries without the minus sign of
(3.27)-(3.28) that its numbers also keep; :func:`lateral_ab` follows the physics and the
numbers (see docs/model.md).
"""
from __future__ import annotations

import math

import numpy as np

from ..core.kernels import kernel
from .params import VehicleParams, Tires


def lateral_ab(v: float, veh: VehicleParams, tires: Tires) -> tuple[np.ndarray, np.ndarray]:
    """A (2x2) and B (2x1) of d/dt [beta, psi dot] = A [beta, psi dot] + B delta, eq (3.30).

    With front and rear cornering stiffness c_f = B_f C_f D_f, c_r = B_r C_r D_r [N/rad]
    (negative in the seed's sign convention):
        A = [[(c_f + c_r)/(m v),       (a c_f - b c_r)/(m v^2) - 1],
             [(a c_f - b c_r)/Izz,     (a^2 c_f + b^2 c_r)/(Izz v)]]
        B = [[-c_f/(m v)], [-a c_f/Izz]]
    For identical tires this is the seed's 2BCD, BCD(a-b), BCD(a^2+b^2) form.

    Parameters
    ----------
    v : float
        Linearisation speed [m/s], > 0.
    """
    if v <= 0:
        raise ValueError(f"linearisation speed must be > 0 m/s, got {v}")
    cf = tires.front.B * tires.front.C * tires.front.D
    cr = tires.rear.B * tires.rear.C * tires.rear.D
    m, izz, a, b = veh.m, veh.Izz, veh.a, veh.b
    A = np.array([
        [(cf + cr) / (m * v), (a * cf - b * cr) / (m * v * v) - 1.0],
        [(a * cf - b * cr) / izz, (a * a * cf + b * b * cr) / (izz * v)],
    ])
    B = np.array([[-cf / (m * v)], [-a * cf / izz]])
    return A, B


def full_ab(v: float, veh: VehicleParams, tires: Tires) -> tuple[np.ndarray, np.ndarray]:
    """A (3x3) and B (3x2) of eq (3.29) for state [v, beta, psi dot] and input [delta, a_r].

    Same physics as :func:`lateral_ab`; v dot = a_r (3.26).
    """
    a2, b2 = lateral_ab(v, veh, tires)
    A = np.zeros((3, 3))
    A[1:, 1:] = a2
    B = np.zeros((3, 2))
    B[1:, 0] = b2[:, 0]
    B[0, 1] = 1.0
    return A, B


def understeer_gradient(veh: VehicleParams, tires: Tires) -> float:
    """K_us = m (b / C_f - a / C_r) / L [rad s^2/m] with C = |B C D| per axle.

    Positive: understeer; negative: oversteer with critical speed sqrt(-L / K_us).
    """
    cf = abs(tires.front.B * tires.front.C * tires.front.D)
    cr = abs(tires.rear.B * tires.rear.C * tires.rear.D)
    return veh.m * (veh.b / cf - veh.a / cr) / veh.wheelbase


def steady_state_yaw_gain(v: float, veh: VehicleParams, tires: Tires) -> float:
    """Closed-form steady-state yaw-rate gain psi dot / delta = v / (L + K_us v^2) [1/s]."""
    return v / (veh.wheelbase + understeer_gradient(veh, tires) * v * v)


def critical_speed(veh: VehicleParams, tires: Tires) -> float:
    """Speed at which an oversteering vehicle becomes unstable, sqrt(-L / K_us) [m/s]; inf if K_us >= 0."""
    k = understeer_gradient(veh, tires)
    return float(np.sqrt(-veh.wheelbase / k)) if k < 0 else float("inf")


def closed_loop_lateral(v: float, veh: VehicleParams, tires: Tires, K: float, k_theta: float,
                        k: float = 1.0) -> np.ndarray:
    """Linearised lateral closed loop of one member on a straight path at speed v [m/s].

    State [beta, psi dot, delta, psi, y] (y: lateral offset from the slot [m]). Plant: (3.30)
    plus delta' = K (omega_ref - psi dot) (3.37 with the scheduled gain at small error,
    K = G_max), psi' = psi dot, y' = v (psi + beta). Outer loop: eqs (2.7)-(2.9) linearised
    about the slot with tanh(e) ~ e: theta* = -k y / v, theta* dot = -k y' / v, so
    omega_ref = -k (psi + beta) + k_theta (-k y / v - psi) (eq 2.8).

    Returns the 5x5 system matrix; the loop is stable when all eigenvalues have negative real part.
    """
    A, B = lateral_ab(v, veh, tires)
    M = np.zeros((5, 5))
    M[:2, :2] = A
    M[:2, 2] = B[:, 0]
    M[2, 0] = -K * k
    M[2, 1] = -K
    M[2, 3] = -K * (k + k_theta)
    M[2, 4] = -K * k_theta * k / v
    M[3, 1] = 1.0
    M[4, 0] = v
    M[4, 3] = v
    return M


STEP_STABILITY_MARGIN = 2.0
"""Largest h |lambda| allowed for the explicit RK4 step (its real-axis limit is 2.785)."""


def stable_blend_speed(veh: VehicleParams, tires: Tires, h: float, floor: float = 1.0) -> float:
    """Lowest speed [m/s] at which the dynamic lateral model may act with RK4 steps of h [s].

    The lateral modes grow as 1/v at low speed (eq 3.30: entries ~ C/(m v), C a^2/(Izz v)), so
    below some speed an explicit step of h diverges. With |lambda(v)| ~ |lambda(1 m/s)| / v,
    the speed where h |lambda| = STEP_STABILITY_MARGIN is h |lambda(1)| / margin; never below
    ``floor``. Car, 10 ms: 1.0 m/s (the floor); small truck with load tires: 4.6 m/s.
    """
    lam1 = float(np.abs(np.linalg.eigvals(lateral_ab(1.0, veh, tires)[0])).max())
    return max(floor, h * lam1 / STEP_STABILITY_MARGIN)


# ------------------------------------------------ the model over a named state row (integrator)

LINEAR_SLOTS = ("X", "Y", "psi", "v", "beta", "r")
"""State slots of the linear model (3.26, 3.30); inputs (delta [rad], a_r [m/s^2])."""
LINEAR_PARAMS = ("a11", "a12", "a21", "a22", "b1", "b2")
"""Columns of the linear model's parameter row: A and B of :func:`lateral_ab`, row by row."""


def linear_params(ab: tuple[np.ndarray, np.ndarray], n: int) -> np.ndarray:
    """(n, 6) parameter rows (LINEAR_PARAMS) of :func:`rhs_into` for A, B = ``ab``."""
    A, B = (np.asarray(m, dtype=float) for m in ab)
    row = [A[0, 0], A[0, 1], A[1, 0], A[1, 1], B[0, 0], B[1, 0]]
    return np.ascontiguousarray(np.tile(row, (n, 1)))


@kernel
def rhs_into(s, u0, u1, P, i, out):
    """The linear model of state row ``s`` (LINEAR_SLOTS) under delta = u0 [rad] and
    a_r = u1 [m/s^2]: position along the course, v dot = a_r, and the lateral pair
    (beta, r) dot = A (beta, r) + B delta (3.26, 3.30); sums in a fixed order (no BLAS)."""
    course = s[2] + s[4]
    out[0] = s[3] * math.cos(course)
    out[1] = s[3] * math.sin(course)
    out[2] = s[5]
    out[3] = u1
    out[4] = (s[4] * P[i, 0] + s[5] * P[i, 1]) + u0 * P[i, 4]
    out[5] = (s[4] * P[i, 2] + s[5] * P[i, 3]) + u0 * P[i, 5]
