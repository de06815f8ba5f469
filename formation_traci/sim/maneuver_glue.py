"""The maneuver planner inside a SUMO run: what sim/sumo_loop.py calls when a scenario has
``[[maneuvers]]`` (nothing of it runs otherwise).

Per SUMO step: :meth:`ManeuverRun.update` hands the planner what was sensed (members and the
vehicles around them in road coordinates), records its events and returns the slots the
governor uses; the step and the recorded signals then evaluate the planner's slot plan with
its exact derivatives (sim/fast_moving.py).
"""
from __future__ import annotations

import numpy as np

from ..control.maneuvers.gap import Others
from ..control.maneuvers.planner import ManeuverPlanner, Sensed
from ..scenario.schema import Scenario
from . import fast_moving
from .governor import LATERAL_MARGIN, time_gap_accel

ROOM_DECEL = 1.0
"""Largest deceleration of the virtual car to open room ahead of goal slots [m/s^2]."""
NO_OTHERS = Others((), np.empty(0), np.empty(0), np.empty(0), np.empty(0), np.empty(0))


def road_room(road):
    """room(s0, s1) -> (d_min, d_max): the narrowest lateral extent of the road over
    [s0, s1] [m] (relative to the reference line, left positive), from road_setup's segments."""
    segments = road.segments

    def room(s0: float, s1: float) -> tuple[float, float]:
        lo, hi = -np.inf, np.inf
        for seg in segments:
            if seg.s1 >= s0 and seg.s0 <= s1:
                lo, hi = max(lo, seg.d_min), min(hi, seg.d_max)
        return lo, hi

    return room


def initial_check_limit(sc: Scenario) -> float | None:
    """How far along the route [m] the initial slots must stay on the road: up to the first
    position-triggered maneuver; only the start when the first maneuver is triggered by time
    or traffic (the planner checks the road ahead before every maneuver). None: no maneuvers."""
    if not sc.maneuvers:
        return None
    first = sc.maneuvers[0].at
    return first.s if first.s is not None else sc.road.start


class ManeuverRun:
    """Planner, slot plan and recording of one run's maneuvers."""

    def __init__(self, sc: Scenario, slots: np.ndarray, road, veh):
        self.ids = [m.id for m in sc.members]
        self.planner = ManeuverPlanner(sc.maneuvers, slots, road.lane_width, sc.maneuver_limits,
                                       veh.length, veh.width, self.ids, road_room(road),
                                       (sc.leader.time_gap, sc.leader.min_gap))

    @property
    def plan(self) -> np.ndarray:
        return self.planner.plan

    def update(self, rec, t, s_vc, m_s, m_d, v_m, active, nb, nb_s, nb_d):
        """Plan the step at time t [s]; returns the slots' along and across (n,) [m] now."""
        others = NO_OTHERS
        if nb is not None and len(nb.ids):
            others = Others(tuple(nb.ids), nb_s, nb_d, nb.length, nb.width, nb.v)
        sensed = Sensed(float(t), float(s_vc), m_s, m_d, v_m, active, others)
        for ev in self.planner.step(sensed):
            rec.add_event(t, ev.kind, "vc", "", ev.detail)
        sl = self.planner.slots(t)
        return sl[:, 0], sl[:, 1]

    def make_room(self, a_vc, s_vc_front, v_vc, half_w, length, active, o_rear, o_d, o_half_w,
                  o_length, o_v, time_gap, min_gap) -> float:
        """The virtual car's acceleration [m/s^2] limited, while a maneuver is due or running,
        by the constant-time-gap law (governor.py) of every goal slot behind the nearest
        vehicle in its lane that is ahead of it or beside it (front bumper ahead of the slot's
        rear; gap = its rear minus the slot's front, negative when beside), bounded below by
        -ROOM_DECEL: the formation drops back gently until its goal slots have room."""
        goal = self.planner.goal()
        if goal is None or not len(o_rear):
            return a_vc
        front = s_vc_front + goal[:, 0]
        rear = front - length
        lane = np.abs(o_d[None, :] - goal[:, 1][:, None]) < o_half_w[None, :] + half_w[:, None] + LATERAL_MARGIN
        cand = lane & ((o_rear + o_length)[None, :] > rear[:, None]) & active[:, None]
        if not cand.any():
            return a_vc
        gaps = np.where(cand, o_rear[None, :] - front[:, None], np.inf)
        i, j = np.nonzero(cand)
        a_goal = time_gap_accel(np.maximum(gaps[i, j], 0.0), v_vc, o_v[j], time_gap, min_gap)
        return min(a_vc, max(float(np.min(a_goal)), -ROOM_DECEL))

    def slot_column(self) -> np.ndarray:
        """Index of the slot each member holds in the present formation (float for the table)."""
        return self.planner.slot_of.astype(float)

    def along_max(self) -> float:
        """Foremost slot of the plan (now or at the end of the running transition) [m]."""
        return float(np.max(self.plan[:, [0, 2]]))

    def step(self, ff, state, t, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl):
        return fast_moving.step(ff, state, self.plan, t, s_vc, v_vc, a_vc, v_cap, a_cap, dt_c, n_ctrl)

    def signals(self, ff, state, t, s_vc, v_vc, a_vc, v_cap, a_cap, out):
        return fast_moving.signals(ff, state, self.plan, t, s_vc, v_vc, a_vc, v_cap, a_cap, out)
