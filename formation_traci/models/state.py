"""The model kinds the compiled step knows and what every law reads of a member's state row.

State rows are indexed by each model's named slots (models/bicycle.py ``S``, models/kinematic.py
``KS``, models/linear.py ``LINEAR_SLOTS``); laws read a member's motion through
:func:`motion_at`, never by slot number, so a model may add slots (an actuator lag) without a
law changing.
"""
from __future__ import annotations

from ..core.kernels import kernel
from .bicycle import S

KINEMATIC = 0
"""Model kind: the unicycle of eq (2.2), state (x, y, psi), input (v, omega)."""
DYNAMIC = 1
"""Model kind: the dynamic bicycle (3.1-3.25), state S, input U."""
LINEAR = 2
"""Model kind: the linearised bicycle (3.26-3.30), state LINEAR_SLOTS, input (delta, a_r)."""


@kernel
def motion_at(kind, x, i, speed_in_i):
    """Speed [m/s], yaw rate [rad/s] and course angle [rad] of member i (the unicycle's
    speed is its applied speed input ``speed_in_i``, as it has no speed state)."""
    if kind == KINEMATIC:
        return speed_in_i, 0.0, x[i, 2]
    return x[i, S.V], x[i, S.R], x[i, S.PSI] + x[i, S.BETA]
