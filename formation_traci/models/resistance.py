"""Longitudinal driving resistances of a member: rolling (eq 3.15), aerodynamic drag, grade.

Each law is written once as a ``@kernel`` (formation_traci/core/kernels.py): the bicycle model's
kernels (models/bicycle.py ``resistance_at``, ``rhs_at``, ``outputs_at``) call them per
scalar, and the same functions take floats or arrays of shape (n,). The force opposes the
motion and acts along the velocity of the centre of gravity (see docs/energy.md for what
that leaves out).

    F_roll  = f_rl(v) m g cos(grade)            f_rl = 0.01 (1 + v / 40.8)   (3.15)
    F_aero  = 0.5 rho c_d A k v^2               k = drag ratio of the formation, 1 alone
    F_grade = m g sin(grade)                    grade > 0 uphill [rad]

Still air: v is the speed relative to the air. ``k`` comes from
:mod:`formation_traci.models.drag_interaction`.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel
from .params import G, RHO_AIR_STANDARD  # noqa: F401  (re-exported: the law's default air)


@kernel
def rolling_coefficient(v):
    """Coefficient of rolling resistance f_rl = 0.01 (1 + v / 40.8) [-], eq (3.15); v [m/s]."""
    return 0.01 * (1.0 + v / 40.8)


@kernel
def rolling_force(v, m, grade):
    """Rolling resistance f_rl(v) m g cos(grade) [N]; v [m/s], m [kg], grade [rad] (3.15)."""
    return rolling_coefficient(v) * m * G * np.cos(grade)


@kernel
def aero_force(v, c_d, area, rho, ratio):
    """Aerodynamic drag 0.5 rho c_d ratio A v^2 [N]; v [m/s], area [m^2], rho [kg/m^3].

    ``ratio`` [-] scales c_d for the vehicles around (1 alone, below 1 in a platoon)."""
    return 0.5 * rho * c_d * ratio * area * v * v


@kernel
def grade_force(m, grade):
    """Weight component along the road m g sin(grade) [N]; grade [rad], positive uphill."""
    return m * G * np.sin(grade)


@kernel
def road_load(v, m, c_d, area, rho, ratio, grade):
    """Total driving resistance [N]: rolling + aerodynamic + grade at speed v [m/s].

    Parameters
    ----------
    v : float or ndarray
        Speed of the centre of gravity [m/s], v >= 0.
    m : float or ndarray
        Mass [kg].
    c_d, area, rho : float or ndarray
        Drag coefficient [-], frontal area [m^2], air density [kg/m^3].
    ratio : float or ndarray
        Drag ratio of the formation around the vehicle [-] (1 alone).
    grade : float or ndarray
        Road grade [rad], positive uphill.
    """
    return rolling_force(v, m, grade) + aero_force(v, c_d, area, rho, ratio) + grade_force(m, grade)
