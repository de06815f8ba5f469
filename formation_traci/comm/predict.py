"""How a member turns the newest virtual-car state it holds into the present one.

On a road the virtual car moves along the reference line with the acceleration the governor
set for the step (``sim/fast.py _advance_vc``: constant acceleration, stop at v = 0). A member
holds (s, v, a) of the beacon and its age tau and predicts

    s(tau) = s + v tau + a tau^2 / 2,   v(tau) = v + a tau,   a(tau) = a   (until v = 0),

then takes the pose, heading, turn rate and its slot from the road map at s(tau). This is the
constant-turn-rate-and-acceleration predictor with the turn rate taken from the map instead of
held: exact whenever the virtual car's acceleration stayed constant over tau, on any road
geometry (a constant-turn-rate predictor is exact only on an arc of constant curvature).
At tau = 0 it returns the state unchanged, bit for bit.
"""
from __future__ import annotations

from ..road.fast_line import frame_at
from ..sim.fast import _advance_vc

predict_along_line = _advance_vc
"""predict_along_line(s [m], v [m/s], a [m/s^2], tau [s]) -> (s, v) at tau later (compiled)."""


def predicted_pose(G, s: float, v: float, a: float, tau: float) -> tuple[float, ...]:
    """The virtual car's (x [m], y [m], heading [rad], v [m/s], yaw rate [rad/s]) predicted tau
    [s] after the state (s, v, a) on the line ``G`` (FastLine.G)."""
    s1, v1 = predict_along_line(s, v, a, tau)
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s1)
    return x, y, heading, v1, v1 * kappa
