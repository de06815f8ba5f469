"""Tire cornering force: Pacejka Magic Formula (3.9)-(3.10) and its linearisation (3.12).

Each law is one compiled function (numba) that takes scalars or arrays alike: the vehicle
kernels call it per member, tests and analysis call it on arrays.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel


@kernel
def magic_formula(alpha, B, C, D, E):
    """Cornering force F = D sin(C atan(B alpha - E (B alpha - atan(B alpha)))) [N].

    Parameters
    ----------
    alpha : float or ndarray
        Tire slip angle [rad], eqs (3.7)-(3.8).
    B, C, D, E : float
        Magic Formula coefficients (Table 3.2).
    """
    ba = B * alpha
    return D * np.sin(C * np.arctan(ba - E * (ba - np.arctan(ba))))


@kernel
def linear_force(alpha, B, C, D):
    """Linearised cornering force F = B C D alpha [N], eq (3.12) (Taylor series at alpha = 0)."""
    return B * C * D * alpha


@kernel
def cornering_force(alpha, B, C, D, E, linear):
    """Eq (3.12) when ``linear`` else eqs (3.9)-(3.10) [N]."""
    if linear:
        return linear_force(alpha, B, C, D)
    return magic_formula(alpha, B, C, D, E)


def cornering_stiffness(B, C, D):
    """Slope of the cornering force at alpha = 0, B C D [N/rad] (negative in the seed's convention)."""
    return B * C * D
