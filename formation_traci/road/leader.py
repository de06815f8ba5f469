"""The virtual car driving along a road reference line (eq 2.3 constrained to the road)."""
from __future__ import annotations

from ..core.states import LeaderState
from ..core.kernels import kernel
from .fast_line import frame_at
from .line_pack import packed
from .geometry import ReferenceLine


@kernel
def road_leader_at(G, s, v, v_dot):
    """The virtual car on the line G at arc length s [m], speed v, acceleration v_dot:
    (x, y, theta, v, omega, v_dot, omega_dot), omega = v kappa(s),
    omega_dot = v_dot kappa + v^2 kappa'(s)."""
    x, y, tx, ty, heading, kappa, kappa_rate = frame_at(G, s)
    return x, y, heading, v, v * kappa, v_dot, v_dot * kappa + v ** 2 * kappa_rate


def road_leader_state(line: ReferenceLine, s: float, v: float, v_dot: float) -> LeaderState:
    """Kinematics of a virtual car on the line at arc length s, eq (2.3).

    The car's pose is the line's point and tangent at s, so its yaw rate follows from the
    curvature: ``omega = v kappa(s)`` and ``omega_dot = v_dot kappa(s) + v^2 kappa'(s)``
    (s_dot = v). Past the line's ends kappa = kappa' = 0 (straight extension).

    Parameters
    ----------
    line : ReferenceLine
        Road reference line.
    s : float
        Arc length of the virtual car [m].
    v : float
        Speed along the line, s_dot [m/s].
    v_dot : float
        Acceleration along the line, s_ddot [m/s^2].

    Returns
    -------
    LeaderState
        Position [m], heading [rad] (unwrapped along the line), v, omega [rad/s], v_dot,
        omega_dot [rad/s^2].
    """
    return LeaderState(*(float(q) for q in road_leader_at(packed(line), float(s), float(v),
                                                           float(v_dot))))
