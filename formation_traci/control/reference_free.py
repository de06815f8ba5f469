"""Reference generator of free-space runs: the virtual car from its speed and yaw-rate
profiles (eq 2.3, RK4 in time), a rigid structure of offsets in its frame (eq 2.4)."""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel, substeps
from .reference import FRAME_VEHICLE, Reference, constant_slots, set_vc_period
from .virtual_car import FreeLeader, free_pose_advance, knot_profile_at, pack_profiles, yaw_offset


@kernel
def free_vc_rows(prof, t, X, Y, th, dt_c, n_sub, vc):
    """Fill vc (n_ctrl, n, 8) with the virtual car at t + j dt_c (every member the same
    copy); returns its pose (x, y, theta) at the end of the step."""
    ow = yaw_offset(prof)
    for j in range(vc.shape[0]):
        tc = t + j * dt_c
        v, v_dot = knot_profile_at(prof, 0, tc)
        w, w_dot = knot_profile_at(prof, ow, tc)
        set_vc_period(vc, j, X, Y, th, v, w, v_dot, w_dot, np.nan)
        X, Y, th = free_pose_advance(prof, tc, X, Y, th, dt_c, n_sub)
    return X, Y, th


class FreeReference:
    """The virtual car of a free-space run and the members' fixed offsets (n, 2) [m]."""

    def __init__(self, leader: FreeLeader, pose, offsets, dt_c: float, n_ctrl: int):
        n = len(offsets)
        self.prof = pack_profiles(leader.speed, leader.yaw_rate)
        self.pose = tuple(float(q) for q in pose)
        self.dt_c, self.n_ctrl = float(dt_c), int(n_ctrl)
        self.n_sub = substeps(dt_c, leader.max_step)
        self.slots = constant_slots(offsets, n_ctrl)
        self.frame = np.full(n, FRAME_VEHICLE, dtype=np.int64)
        self.active = np.ones(n, dtype=bool)
        self.no_cap = np.full(n, np.inf)
        self._next = None

    def plan(self, t: float, sensed=None) -> list:
        """Nothing to ask of the world (control/reference.py WorldCommand)."""
        return []

    def reference(self, t: float, sensed=None) -> Reference:
        """The reference of the step starting at t [s] (from the current pose); the members
        in the run are those the world ``sensed`` (sim/world.py), all without it."""
        vc = np.empty((self.n_ctrl, len(self.frame), 8))
        self._next = free_vc_rows(self.prof, float(t), *self.pose, self.dt_c, self.n_sub, vc)
        truth = vc[0, 0].copy() if len(self.frame) else np.array([*self.pose, 0, 0, 0, 0, np.nan])
        active = self.active if sensed is None else sensed.active
        return Reference(float(t), self.dt_c, vc, self.slots, self.frame, active,
                         self.no_cap, self.no_cap, truth=truth)

    def commit(self) -> None:
        """The step was taken: the pose moves to the end of it."""
        self.pose = tuple(float(q) for q in self._next)

    def stop_reason(self, t: float):
        return None


def warm_kernels() -> None:
    """Compile (or load) this module's kernels for the argument types a free-space run passes,
    on zero members (sim/warm.py: one compilation covers every scenario kind)."""
    free_vc_rows(np.zeros(8), 0.0, 0.0, 0.0, 0.0, 0.01, 1, np.zeros((0, 0, 8)))
