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
A slot that moves (a maneuver: dx(t), dy(t)) adds the terms of its own rates, see
:func:`road_target_at`.
"""
from __future__ import annotations

import numpy as np

from ..core.states import Targets
from ..core.kernels import kernel
from .fast_line import frame_at
from .line_pack import packed
from .geometry import ReferenceLine


@kernel
def road_target_at(G, s, v, v_dot, dx, dy, dx_dot, dy_dot, dx_ddot, dy_ddot):
    """Desired point of a road-frame slot (dx, dy) for the virtual car at arc length s [m],
    speed v and acceleration v_dot along the line G (road/fast_line.py): (px, py, vx, vy,
    ax, ay). With sigma = s + dx, sigma' = v + dx', sigma'' = v_dot + dx'' and
    stretch = 1 - dy kappa (all at sigma):

        p'  = sigma' stretch t + dy' n,
        p'' = [sigma'' stretch - sigma'^2 dy kappa' - 2 sigma' dy' kappa] t
              + [sigma'^2 stretch kappa + dy''] n.
    """
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s + dx)
    nx = -ty
    ny = tx
    sv = v + dx_dot
    sa = v_dot + dx_ddot
    stretch = 1.0 - dy * kappa
    vs = sv * stretch
    ct = sa * stretch - sv * sv * dy * kappa_rate - 2.0 * sv * dy_dot * kappa
    cn = sv * sv * stretch * kappa + dy_ddot
    return (x + dy * nx, y + dy * ny, vs * tx + dy_dot * nx, vs * ty + dy_dot * ny,
            ct * tx + cn * nx, ct * ty + cn * ny)


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
    G = packed(line)
    T = np.array([road_target_at(G, float(s), float(v), float(v_dot), float(dx), float(dy),
                                 0.0, 0.0, 0.0, 0.0) for dx, dy in offsets], dtype=float)
    T = T.reshape(len(offsets), 6)
    return Targets(T[:, 0:2], T[:, 2:4], T[:, 4:6])
