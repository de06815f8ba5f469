"""The virtual car in free space: a unicycle (eq 2.3) driven by speed and yaw-rate profiles."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..control.formation import LeaderState
from .integrate import substeps
from .profile import Profile


@dataclass(frozen=True)
class FreeLeader:
    """Virtual car whose v(t) [m/s] and omega(t) [rad/s] follow profiles.

    The pose is integrated with RK4 in time; v, omega and their derivatives are exact.
    """

    speed: Profile  # [m/s]
    yaw_rate: Profile  # [rad/s]
    max_step: float  # [s]

    def sample(self, t: float, pose: tuple[float, float, float]) -> LeaderState:
        """Leader kinematics at time t [s] with pose (x, y, theta) [m, m, rad]."""
        v, v_dot = self.speed(t)
        w, w_dot = self.yaw_rate(t)
        return LeaderState(pose[0], pose[1], pose[2], v, w, v_dot, w_dot)

    def _deriv(self, t, th):
        v = self.speed(t)[0]
        return v * math.cos(th), v * math.sin(th), self.yaw_rate(t)[0]

    def advance(self, t: float, pose: tuple[float, float, float], dt: float):
        """Pose at t + dt, integrating eq (2.3) with RK4 sub-steps of at most max_step."""
        n = substeps(dt, self.max_step)
        h = dt / n
        x, y, th = pose
        for i in range(n):
            t0 = t + i * h
            k1 = self._deriv(t0, th)
            k2 = self._deriv(t0 + h / 2, th + h / 2 * k1[2])
            k3 = self._deriv(t0 + h / 2, th + h / 2 * k2[2])
            k4 = self._deriv(t0 + h, th + h * k3[2])
            x += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            y += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            th += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        return x, y, th
