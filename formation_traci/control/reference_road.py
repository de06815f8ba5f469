"""Reference generator of road runs: the virtual car along the reference line with the
traffic-aware governor's acceleration (control/governor.py) made jerk-limited by the
longitudinal planner (control/longitudinal.py), slots in road or vehicle frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels import kernel
from ..road.leader import road_leader_at
from .governor import column_caps, governor_step
from .longitudinal import LongitudinalPlanner, PlannerParams
from .reference import FRAME_ROAD, FRAME_VEHICLE, Reference, constant_slots, set_vc_period
from .virtual_car import along_line_advance, knot_profile_at


@kernel
def road_vc_rows(G, s, v, a, dt_c, vc):
    """Fill vc (n_ctrl, n, 8) with the virtual car on line G at the start of every control
    period (constant acceleration a over the step); returns (s, v) at the end of the step."""
    for j in range(vc.shape[0]):
        X, Y, th, vv, om, vd, omd = road_leader_at(G, s, v, a)
        set_vc_period(vc, j, X, Y, th, vv, om, vd, omd, s)
        s, v = along_line_advance(s, v, a, dt_c)
    return s, v


@dataclass(frozen=True)
class GovernorLimits:
    """The governor's settings (scenario [leader], capped by the road's adhesion)."""

    time_gap: float  # [s]
    min_gap: float  # [m]
    accel_max: float  # [m/s^2]
    decel_max: float  # comfortable [m/s^2]
    decel_emergency: float  # [m/s^2]


class RoadReference:
    """The virtual car of a road run: s [m] and v [m/s] along the line, the governor's
    acceleration per step; ``slots`` / ``rigid`` (n, 2) with NaN rows for the other kind."""

    def __init__(self, G, length: float, slots, rigid, is_road, s0: float, v0: float,
                 speed_profile, limits: GovernorLimits, half_w, d_front,
                 end_margin: float, dt_c: float, n_ctrl: int):
        self.G, self.length = G, float(length)
        self.is_road = np.asarray(is_road, dtype=bool)
        self.frame = np.where(self.is_road, FRAME_ROAD, FRAME_VEHICLE).astype(np.int64)
        offsets = np.where(self.is_road[:, None], np.nan_to_num(slots), np.nan_to_num(rigid))
        self.slot_d = np.nan_to_num(np.asarray(slots, float)[:, 1])
        self.along = offsets[:, 0]  # slot ahead of the virtual car [m]
        self.slots = constant_slots(offsets, n_ctrl)
        self.s, self.v = float(s0), float(v0)
        self.prof = speed_profile.packed()
        # d_front: CoG to front bumper [m], one or one per member (a mixed formation)
        self.limits, self.half_w, self.d_front = limits, half_w, np.asarray(d_front, float)
        self.end_margin = float(end_margin)
        self.dt_c, self.n_ctrl = float(dt_c), int(n_ctrl)
        self._next = None
        self.longitudinal = LongitudinalPlanner(len(self.frame), PlannerParams(decel_comfort=limits.decel_max))
        self._v_prev = None  # members' speed at the previous step [m/s]

    def governor(self, t: float, sensed):
        """(a_vc, gap, lead index, v_cap, a_cap) from the members' and neighbours' road
        coordinates (control/governor.py); members of one column share the tightest caps
        ahead of them (``column_caps``)."""
        lim = self.limits
        slot_d = np.where(self.is_road, self.slot_d, sensed.m_d)
        v_set, v_set_dot = knot_profile_at(self.prof, 0, float(t))
        df = self.d_front
        slot_s = self.s + self.along
        a_vc, gap, lead_idx, v_cap, a_cap = governor_step(
            sensed.m_s + df, sensed.m_d, slot_s + df, slot_d, self.half_w,
            sensed.v_m, sensed.active, self.v, v_set, v_set_dot, sensed.nb_rear, sensed.nb_d,
            sensed.nb_half_w, sensed.nb_v, lim.time_gap, lim.min_gap, lim.accel_max,
            lim.decel_emergency)
        v_cap, a_cap = column_caps(slot_s, slot_d, self.half_w, sensed.active, v_cap, a_cap)
        return a_vc, gap, lead_idx, v_cap, a_cap

    def reference(self, t: float, sensed) -> Reference:
        """The reference of the step starting at t [s]."""
        a_request, gap, lead_idx, v_cap_req, a_cap_req = self.governor(t, sensed)
        a_vc, v_cap, a_cap = self.smooth(sensed, a_request, v_cap_req, a_cap_req)
        vc = np.empty((self.n_ctrl, len(self.frame), 8))
        self._next = road_vc_rows(self.G, self.s, self.v, a_vc, self.dt_c, vc)
        truth = vc[0, 0].copy()  # period 0: road_leader_at(G, s, v, a_vc) and s
        return Reference(float(t), self.dt_c, vc, self.slots, self.frame, sensed.active, v_cap,
                         a_cap, line=self.G, truth=truth,
                         info={"a_vc": a_vc, "gap": gap, "lead_idx": lead_idx,
                               "a_request": a_request, "a_cap_request": a_cap_req,
                               "emergency": self.longitudinal.emergency_vc,
                               "emergency_members": self.longitudinal.emergency.copy()})

    def smooth(self, sensed, a_request, v_cap, a_cap):
        """The governor's requests through the jerk-limited planner (control/longitudinal.py):
        (a_vc [m/s^2], v_cap [m/s] (all +inf: folded into a_cap), a_cap [m/s^2]). The members'
        acceleration is their mean over the previous step. Members not (or no longer) in the
        run get no caps (and so no emergency)."""
        dt = self.dt_c * self.n_ctrl
        off = ~np.asarray(sensed.active, dtype=bool)
        if off.any():
            v_cap, a_cap = np.where(off, np.inf, v_cap), np.where(off, np.inf, a_cap)
        v_m = np.asarray(sensed.v_m, dtype=float)
        a_m = np.zeros(len(v_m)) if self._v_prev is None else (v_m - self._v_prev) / dt
        self._v_prev = v_m.copy()
        a_vc, v_cap, a_cap = self.longitudinal.step(a_request, v_cap, a_cap, v_m, a_m, dt)
        if off.any():  # a cap being eased out goes with its member
            a_cap[off] = np.inf
        return a_vc, v_cap, a_cap

    def commit(self) -> None:
        self.s, self.v = (float(q) for q in self._next)

    def stop_reason(self, t: float):
        """('end_of_road', message) when the formation's front nears the route's end."""
        if self.s + float(np.max(self.along + self.d_front)) + self.end_margin > self.length:
            return ("end_of_road",
                    f"formation front within {self.end_margin} m of the route end",
                    f"end of the route reached at t = {t:.2f} s")
        return None
