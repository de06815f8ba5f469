"""The virtual car (eq 2.3): its speed and yaw-rate profiles, its pose in free space, its
progress along a road's reference line.

Laws as compiled kernels; :class:`Profile` and :class:`FreeLeader` are thin wrappers for
Python callers (set-up, the governor's set speed, tests).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..core.kernels import kernel, substeps
from ..models.integrator import KINEMATIC, rk4_row
from ..core.states import LeaderState


@kernel
def knot_profile_at(buf, off, t):
    """Value and time derivative at t [s] of the profile packed at buf[off:] as
    [n, smooth, t_1..t_n, v_1..v_n]: held outside the knots, linear or smoothstep (C1)
    between them."""
    n = int(buf[off])
    smooth = buf[off + 1] != 0.0
    ot = off + 2
    ov = off + 2 + n
    if n == 1 or t <= buf[ot]:
        return buf[ov], 0.0
    if t >= buf[ot + n - 1]:
        return buf[ov + n - 1], 0.0
    i = 0  # np.searchsorted(ts, t, side="right") - 1
    while i + 1 < n and buf[ot + i + 1] <= t:
        i += 1
    t0 = buf[ot + i]
    t1 = buf[ot + i + 1]
    v0 = buf[ov + i]
    v1 = buf[ov + i + 1]
    span = t1 - t0
    s = (t - t0) / span
    if not smooth:
        return v0 + (v1 - v0) * s, (v1 - v0) / span
    return v0 + (v1 - v0) * s * s * (3.0 - 2.0 * s), (v1 - v0) * 6.0 * s * (1.0 - s) / span


@dataclass(frozen=True, slots=True)
class Profile:
    """A scalar signal of time given at knots, held constant outside them.

    ``interp="linear"`` joins the knots with straight lines (derivative piecewise
    constant); ``interp="smooth"`` joins them with a smoothstep (C1: derivative zero at
    every knot), which keeps jerk finite.
    """

    t: tuple[float, ...]  # knot times [s], strictly increasing
    values: tuple[float, ...]  # values at the knots [signal unit]
    interp: Literal["linear", "smooth"] = "linear"

    @classmethod
    def constant(cls, value: float) -> "Profile":
        return cls((0.0,), (float(value),))

    def packed(self) -> np.ndarray:
        """[n, smooth, t..., values...] for :func:`knot_profile_at`."""
        if self.interp not in ("linear", "smooth"):
            raise ValueError(f"unknown profile interpolation {self.interp!r}")
        return np.array([len(self.t), self.interp == "smooth", *self.t, *self.values], float)

    def __call__(self, t: float) -> tuple[float, float]:
        """Value and time derivative at time t [s]."""
        v, d = knot_profile_at(self.packed(), 0, float(t))
        return float(v), float(d)


def pack_profiles(speed: Profile, yaw_rate: Profile) -> np.ndarray:
    """Speed and yaw-rate profiles in one buffer: the speed's at 0, the yaw rate's at
    ``2 + 2 len(speed.t)`` (:func:`yaw_offset`)."""
    return np.concatenate([speed.packed(), yaw_rate.packed()])


@kernel
def yaw_offset(prof):
    return 2 + 2 * int(prof[0])


_NO_PARAMS = np.zeros((1, 1))


@kernel
def free_pose_advance(prof, t, X, Y, th, dt, n_sub):
    """Pose (x, y, theta) of the virtual car at t + dt: eq (2.3), the unicycle, integrated by
    models/integrator.py's RK4 in n_sub sub-steps with v(t) and omega(t) from the packed
    profiles at the stage times."""
    h = dt / n_sub
    ow = yaw_offset(prof)
    stages = np.empty((n_sub, 3, 2))
    for q in range(n_sub):
        t0 = t + q * h
        for c in range(3):
            tc = t0 if c == 0 else (t0 + h / 2 if c == 1 else t0 + h)
            stages[q, c, 0] = knot_profile_at(prof, 0, tc)[0]
            stages[q, c, 1] = knot_profile_at(prof, ow, tc)[0]
    s = np.empty(3)
    s[0] = X
    s[1] = Y
    s[2] = th
    rk4_row(KINEMATIC, s, 0.0, 0.0, _NO_PARAMS, 0, h, n_sub, np.empty((5, 3)), stages)
    return s[0], s[1], s[2]


@kernel
def along_line_advance(s, v, a, dt):
    """Arc length s [m] and speed v [m/s] after dt [s] at constant acceleration a [m/s^2];
    the car stops at v = 0 (no reversing)."""
    if v + a * dt >= 0.0:
        return s + v * dt + 0.5 * a * dt * dt, v + a * dt
    t_stop = v / -a
    return s + v * t_stop + 0.5 * a * t_stop * t_stop, 0.0


@dataclass(frozen=True)
class FreeLeader:
    """Virtual car whose v(t) [m/s] and omega(t) [rad/s] follow profiles (free space).

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

    def advance(self, t: float, pose: tuple[float, float, float], dt: float):
        """Pose at t + dt, integrating eq (2.3) with RK4 sub-steps of at most max_step."""
        n = substeps(dt, self.max_step)
        out = free_pose_advance(pack_profiles(self.speed, self.yaw_rate), float(t),
                                float(pose[0]), float(pose[1]), float(pose[2]), float(dt), n)
        return tuple(float(q) for q in out)
