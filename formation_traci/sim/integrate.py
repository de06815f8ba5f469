"""Fixed-step Runge-Kutta integration of any ``rhs(x, u, p) -> dx`` with the input held."""
from __future__ import annotations

import math

MAX_PHYSICS_STEP = 0.01
"""Largest internal step [s]: the car's lateral dynamics need it at low speed (docs/model.md)."""


def rk4_step(rhs, x, u, p, h):
    """One classical 4th-order Runge-Kutta step of length h [s] with u held constant."""
    k1 = rhs(x, u, p)
    k2 = rhs(x + 0.5 * h * k1, u, p)
    k3 = rhs(x + 0.5 * h * k2, u, p)
    k4 = rhs(x + h * k3, u, p)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def substeps(dt: float, max_step: float) -> int:
    """Number of equal sub-steps of at most ``max_step`` [s] that cover ``dt`` [s]."""
    return max(1, math.ceil(dt / max_step - 1e-9))


def integrate(rhs, x, u, p, dt, max_step=MAX_PHYSICS_STEP, project=None):
    """Advance x by dt [s] in equal RK4 sub-steps of at most ``max_step`` [s].

    ``project(x, p)``, if given, enforces state constraints after every sub-step.
    """
    n = substeps(dt, max_step)
    h = dt / n
    for _ in range(n):
        x = rk4_step(rhs, x, u, p, h)
        if project is not None:
            x = project(x, p)
    return x
