"""Formation targets given in road coordinates (the road-following analogue of eq 2.4).

On a curved road a rigid virtual structure (eq 2.4) puts members beside the virtual car
off their lanes: a slot 3.5 m to the left of the car is not on the next lane once the road
bends. Here a slot is (dx, dy) in Frenet coordinates of the reference line instead: member
i's desired point is dx_i ahead along the line and dy_i to its left,

    p_i = c(s + dx_i) + dy_i n(s + dx_i).

With the Frenet-Serret formulas per unit arc length (t' = kappa n, n' = -kappa t) and
s_dot = v, s_ddot = v_dot of the virtual car, the exact time derivatives are

    p_i'  = v (1 - dy_i kappa) t,
    p_i'' = v_dot (1 - dy_i kappa) t + v^2 [ -dy_i kappa' t + (1 - dy_i kappa) kappa n ],

all evaluated at s + dx_i. They feed eqs (2.5)-(2.9) in place of the derivatives of (2.4).
On a straight line they equal :func:`~formation_traci.control.formation.rigid_targets`.
"""
from __future__ import annotations

import numpy as np

from ..control.formation import Targets
from .geometry import ReferenceLine


def road_targets(line: ReferenceLine, s: float, v: float, v_dot: float,
                 offsets: np.ndarray) -> Targets:
    """Desired position, velocity and acceleration of slots fixed in road coordinates.

    Parameters
    ----------
    line : ReferenceLine
        Road reference line (s = 0 at its start).
    s : float
        Arc length of the virtual car [m].
    v : float
        Speed of the virtual car along the line, s_dot [m/s].
    v_dot : float
        Acceleration of the virtual car along the line, s_ddot [m/s^2].
    offsets : ndarray, shape (n, 2)
        (dx, dy) of each slot: dx along the line ahead of the car [m], dy to the left of
        the line [m] (e.g. from :func:`~formation_traci.road.geometry.lane_offsets`).
        Valid for ``|dy| < 1 / |kappa|``.

    Returns
    -------
    Targets
        p [m], v [m/s] and a [m/s^2], each shape (n, 2). Slots past the line's ends lie
        on its straight extension.
    """
    offsets = np.asarray(offsets, dtype=float)
    if offsets.ndim != 2 or offsets.shape[1] != 2:
        raise ValueError(f"offsets must have shape (n, 2), got {offsets.shape}")
    dx, dy = offsets[:, 0], offsets[:, 1]
    f = line.frame(float(s) + dx)
    kappa, kappa_rate = f.curvature, f.curvature_rate
    t, n = f.tangent, f.normal
    stretch = 1.0 - dy * kappa  # speed of the offset point per unit arc length [-]
    p = f.position + dy[:, None] * n
    vel = (v * stretch)[:, None] * t
    acc = ((v_dot * stretch - v * v * dy * kappa_rate)[:, None] * t
           + (v * v * stretch * kappa)[:, None] * n)
    return Targets(p, vel, acc)
