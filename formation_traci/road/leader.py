"""The virtual car driving along a road reference line (eq 2.3 constrained to the road)."""
from __future__ import annotations

from ..control.formation import LeaderState
from .geometry import ReferenceLine


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
    f = line.frame(float(s))
    kappa, kappa_rate = float(f.curvature), float(f.curvature_rate)
    return LeaderState(
        x=float(f.position[0]),
        y=float(f.position[1]),
        theta=float(f.heading),
        v=float(v),
        omega=float(v) * kappa,
        v_dot=float(v_dot),
        omega_dot=float(v_dot) * kappa + float(v) ** 2 * kappa_rate,
    )
