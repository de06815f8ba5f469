"""Fixed-step classical Runge-Kutta (RK4) of the members' vehicle models, input held.

One RK4 for both models: :func:`rk4_at` integrates one vehicle of either kind (the unicycle
uses the first three of the seven state slots) and applies the bicycle's state constraints
after every sub-step; :func:`integrate` does it for every row of a state array.
"""
from __future__ import annotations

import numpy as np

from ..kernels import kernel, substeps
from ..models import bicycle, kinematic
from ..models.params import _SMAX

MAX_PHYSICS_STEP = 0.01
"""Largest internal step [s]: the car's lateral dynamics need it at low speed (docs/model.md)."""

KINEMATIC = 0
"""Model kind: the unicycle of eq (2.2), state (x, y, psi), input (v, omega)."""
DYNAMIC = 1
"""Model kind: the dynamic bicycle (3.1-3.25), state S, input U."""


@kernel
def _rhs(kind, psi, v, beta, r, delta, u0, u1, P, i):
    if kind == DYNAMIC:
        return bicycle.rhs_at(psi, v, beta, r, delta, u0, u1, P, i)
    dx, dy, dpsi = kinematic.rhs_at(psi, u0, u1)
    return dx, dy, dpsi, 0.0, 0.0, 0.0, 0.0


@kernel
def rk4_at(kind, X, Y, psi, v, beta, r, delta, u0, u1, P, i, h, n_sub):
    """``n_sub`` RK4 sub-steps of length h [s] of vehicle i with the input (u0, u1) held;
    returns the seven state slots (zeros beyond psi for the unicycle)."""
    hh = 0.5 * h
    h6 = h / 6.0
    for _ in range(n_sub):
        k1 = _rhs(kind, psi, v, beta, r, delta, u0, u1, P, i)
        k2 = _rhs(kind, psi + hh * k1[2], v + hh * k1[3], beta + hh * k1[4], r + hh * k1[5],
                  delta + hh * k1[6], u0, u1, P, i)
        k3 = _rhs(kind, psi + hh * k2[2], v + hh * k2[3], beta + hh * k2[4], r + hh * k2[5],
                  delta + hh * k2[6], u0, u1, P, i)
        k4 = _rhs(kind, psi + h * k3[2], v + h * k3[3], beta + h * k3[4], r + h * k3[5],
                  delta + h * k3[6], u0, u1, P, i)
        X = X + h6 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        Y = Y + h6 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        psi = psi + h6 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2])
        v = v + h6 * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3])
        beta = beta + h6 * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4])
        r = r + h6 * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5])
        delta = delta + h6 * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6])
        if kind == DYNAMIC:
            v, delta = bicycle.project_at(v, delta, P[i, _SMAX])
    return X, Y, psi, v, beta, r, delta


@kernel
def integrate_rows(kind, x, u, P, dt, n_sub):
    """Every row of x (n, 7 or 3) advanced by dt [s] in n_sub RK4 sub-steps; x unchanged."""
    n, m = x.shape
    out = np.empty((n, m))
    h = dt / n_sub
    for i in range(n):
        s = np.zeros(7)
        for j in range(m):
            s[j] = x[i, j]
        res = rk4_at(kind, s[0], s[1], s[2], s[3], s[4], s[5], s[6], u[i, 0], u[i, 1], P, i,
                     h, n_sub)
        for j in range(m):
            out[i, j] = res[j]
    return out


def integrate(kind: int, x, u, P, dt: float, max_step: float = MAX_PHYSICS_STEP) -> np.ndarray:
    """Advance states x by dt [s] in equal RK4 sub-steps of at most ``max_step`` [s].

    ``kind``: :data:`DYNAMIC` (x (n, 7), u (n, 2), P from models.params.pack_params) or
    :data:`KINEMATIC` (x (n, 3); P unused, may be None)."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    u = np.ascontiguousarray(np.broadcast_to(u, (len(x), 2)), dtype=np.float64)
    P = np.zeros((len(x), 1)) if P is None else np.ascontiguousarray(P, dtype=np.float64)
    return integrate_rows(kind, x, u, P, float(dt), substeps(dt, max_step))
