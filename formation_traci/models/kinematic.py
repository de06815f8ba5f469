"""Kinematic unicycle, eq (2.2): the ideal-tracking comparison of chapter 2.

State (columns of ``x``, shape (n, 3)), see :class:`KS`: X, Y [m], PSI [rad].
Input (columns of ``u``, shape (n, 2)), see :class:`KU`: V [m/s], OMEGA [rad/s], applied
exactly (the formation controller's references, eqs 2.6 and 2.8).
"""
from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from ..core.kernels import kernel, maximum


class KS(IntEnum):
    """State slots of the unicycle."""

    X = 0
    Y = 1
    PSI = 2


class KU(IntEnum):
    """Input slots of the unicycle."""

    V = 0
    OMEGA = 1


N_STATES = len(KS)


@kernel
def rhs_at(psi, v_in, omega):
    """x dot = v cos(theta), y dot = v sin(theta), theta dot = w, eq (2.2).

    The speed input is floored at 0: the vehicles of the seed only move forward."""
    v = maximum(v_in, 0.0)
    return v * math.cos(psi), v * math.sin(psi), omega


@kernel
def rhs_into(s, u0, u1, P, i, out):
    """:func:`rhs_at` of the state row ``s`` (slots :class:`KS`) under (v, omega) into ``out``
    (the form models/integrator.py integrates; ``P``, ``i`` unused)."""
    out[KS.X], out[KS.Y], out[KS.PSI] = rhs_at(s[KS.PSI], u0, u1)


def rhs(x, u, p=None):
    """:func:`rhs_at` for every row of x (n, 3) under u (n, 2); ``p`` is unused."""
    dx = np.empty_like(np.asarray(x, dtype=float))
    for i in range(len(dx)):
        dx[i] = rhs_at(float(x[i, KS.PSI]), float(u[i, KU.V]), float(u[i, KU.OMEGA]))
    return dx
