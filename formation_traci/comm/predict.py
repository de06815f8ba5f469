"""How a member turns the newest virtual-car state it holds into the present one.

**On a road** the virtual car moves along the reference line with the acceleration the
governor set for the step (``control/virtual_car.py along_line_advance``: constant acceleration, stop at v = 0).
A member holds (s, v, a) of the beacon and its age tau and predicts

    s(tau) = s + v tau + a tau^2 / 2,   v(tau) = v + a tau,   a(tau) = a   (until v = 0),

then takes the pose, heading, turn rate and its slot from the road map at s(tau)
(:func:`predict_along_line`). This is the constant-turn-rate-and-acceleration predictor with
the turn rate taken from the map instead of held: exact whenever the virtual car's
acceleration stayed constant over tau, on any road geometry (a constant-turn-rate predictor is
exact only on an arc of constant curvature).

**In free space** there is no map: :func:`predict_planar` holds the turn rate omega and the
acceleration a of the beacon (CTRA) and integrates the unicycle (eq 2.3) over tau in closed
form: exact for a virtual car with constant turn rate and constant acceleration (a circle at
constant speed, a spiral when accelerating).

Both return the state unchanged, bit for bit, at tau = 0.
"""
from __future__ import annotations

import math

from ..control.virtual_car import along_line_advance
from ..core.kernels import kernel
from ..road.fast_line import frame_at

predict_along_line = along_line_advance
"""predict_along_line(s [m], v [m/s], a [m/s^2], tau [s]) -> (s, v) at tau later (compiled)."""

_STRAIGHT = 1e-6
"""Below this |omega tau| [rad] the planar predictor uses its series (no division by omega)."""


def predicted_pose(G, s: float, v: float, a: float, tau: float) -> tuple[float, ...]:
    """The virtual car's (x [m], y [m], heading [rad], v [m/s], yaw rate [rad/s]) predicted tau
    [s] after the state (s, v, a) on the line ``G`` (road/line_pack.py FastLine.G)."""
    s1, v1 = predict_along_line(s, v, a, tau)
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s1)
    return x, y, heading, v1, v1 * kappa


@kernel
def predict_planar(x, y, th, v, w, a, tau):
    """Pose and speed (x [m], y [m], theta [rad], v [m/s]) tau [s] after (x, y, theta, v) with
    the turn rate w [rad/s] and the acceleration a [m/s^2] held (the speed stops at 0)."""
    if tau == 0.0:
        return x, y, th, v
    if a < 0.0 and v + a * tau < 0.0:
        tau_move = v / -a  # it stands still after this
    else:
        tau_move = tau
    th1 = th + w * tau_move
    v1 = v + a * tau_move
    c, s = math.cos(th), math.sin(th)
    wt = w * tau_move
    if abs(wt) < _STRAIGHT:
        t1, t2, t3, t4 = tau_move, tau_move ** 2, tau_move ** 3, tau_move ** 4
        m0 = v * t1 + a * t2 / 2.0
        m1 = v * t2 / 2.0 + a * t3 / 3.0
        m2 = v * t3 / 6.0 + a * t4 / 8.0
        dx = m0 * c - w * m1 * s - w * w * m2 * c
        dy = m0 * s + w * m1 * c - w * w * m2 * s
    else:
        c1, s1 = math.cos(th1), math.sin(th1)
        dx = (v1 * s1 - v * s) / w + a * (c1 - c) / (w * w)
        dy = (-v1 * c1 + v * c) / w + a * (s1 - s) / (w * w)
    return x + dx, y + dy, th1, max(v1, 0.0)
