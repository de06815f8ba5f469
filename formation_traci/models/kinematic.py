"""Kinematic unicycle, eq (2.2): the ideal-tracking comparison of chapter 2.

State (columns of ``x``, shape (n, 3)), see :class:`KS`: X, Y [m], PSI [rad].
Input (columns of ``u``, shape (n, 2)), see :class:`KU`: V [m/s], OMEGA [rad/s], applied
exactly (the formation controller's references, eqs 2.6 and 2.8).
"""
from __future__ import annotations

from enum import IntEnum

import numpy as np


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


def rhs(x, u, p=None):
    """x dot = v cos(theta), y dot = v sin(theta), theta dot = w, eq (2.2); shape (n, 3).

    The speed input is floored at 0: the vehicles of the seed only move forward.
    ``p`` is unused and kept for the common ``rhs(x, u, p)`` signature.
    """
    v = np.maximum(u[:, KU.V], 0.0)
    dx = np.empty_like(x)
    dx[:, KS.X] = v * np.cos(x[:, KS.PSI])
    dx[:, KS.Y] = v * np.sin(x[:, KS.PSI])
    dx[:, KS.PSI] = u[:, KU.OMEGA]
    return dx
