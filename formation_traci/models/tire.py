"""Tire cornering force: Pacejka Magic Formula (3.9)-(3.10) and its linearisation (3.12)."""
from __future__ import annotations

import numpy as np


def magic_formula(alpha, B, C, D, E):
    """Cornering force F = D sin(C atan(B alpha - E (B alpha - atan(B alpha)))) [N].

    Parameters
    ----------
    alpha : array_like
        Tire slip angle [rad], eqs (3.7)-(3.8).
    B, C, D, E : float or array_like
        Magic Formula coefficients (Table 3.2); broadcast against ``alpha``.
    """
    ba = B * alpha
    return D * np.sin(C * np.arctan(ba - E * (ba - np.arctan(ba))))


def linear_force(alpha, B, C, D):
    """Linearised cornering force F = B C D alpha [N], eq (3.12) (Taylor series at alpha = 0)."""
    return B * C * D * alpha


def cornering_force(alpha, B, C, D, E, linear: bool):
    """Eq (3.12) when ``linear`` else eqs (3.9)-(3.10) [N]."""
    if linear:
        return linear_force(alpha, B, C, D)
    return magic_formula(alpha, B, C, D, E)


def cornering_stiffness(B, C, D):
    """Slope of the cornering force at alpha = 0, B C D [N/rad] (negative in the seed's convention)."""
    return B * C * D
