"""Maneuvers through the reference seam (docs/architecture.md): a road reference generator
that consults the planner every step, and a transform that writes the planner's slot plan
into the step's Reference.

* :class:`ManeuverRoadReference` (a control/reference_road.py RoadReference): before the
  governor runs it hands the planner what the world sensed (members and the vehicles around
  them in road coordinates), records the planner's events, gives the governor the slots of
  this instant, and limits the virtual car's acceleration by :func:`room_accel` while a
  maneuver is running, due, or about to become due (look-ahead below); the request then
  passes the jerk-limited planner (control/longitudinal.py) like every road run's;
* :class:`PlanSlots` (a Reference transform): every member's slot and its exact rates at
  each control period of the step, from the plan (transition.py). The kernels are untouched:
  road/targets.py ``road_target_at`` takes the slot's rates.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..governor import LATERAL_MARGIN, time_gap_accel
from ..reference import Reference, WorldCommand
from ..reference_road import RoadReference
from .gap import Others
from .planner import MERGE_SHIFT, ManeuverPlanner, PlannerEvent, Situation
from .transition import plan_slots_into

ROOM_DECEL = 1.0
"""Largest deceleration of the virtual car to open room ahead of goal slots [m/s^2]."""


def room_lookahead(tau: float, jerk_max: float) -> float:
    """Look-ahead of the room-making law [s]: the time the jerk-limited planner
    (control/longitudinal.py: lag ``tau`` [s], jerk bound ``jerk_max`` [m/s^3]) takes to bring
    the virtual car from cruising to ROOM_DECEL, tau + ROOM_DECEL / jerk_max (1.75 s with the
    defaults). The law starts this long before a time or position trigger fires and acts on
    the gaps predicted this far ahead, so the planned deceleration is there when the gap
    check needs it (docs/maneuvers.md, 'Gap check')."""
    return tau + ROOM_DECEL / jerk_max

_NONE = np.empty(0)
NO_OTHERS = Others((), _NONE, _NONE, _NONE, _NONE, _NONE)


class PlanSlots:
    """Reference transform: slots (n_ctrl, n, 6) with rates from the planner's plan."""

    def __init__(self, planner: ManeuverPlanner):
        self.planner = planner

    def __call__(self, ref: Reference) -> Reference:
        slots = plan_slots_into(self.planner.plan, float(ref.t), float(ref.dt),
                                np.empty_like(ref.slots))
        return ref.with_(slots=slots)


class Around(NamedTuple):
    """The vehicles around the goal slots (k of them) as :func:`room_accel` takes them."""

    rear: np.ndarray  # rear bumper's arc length [m]
    d: np.ndarray  # offset [m]
    half_w: np.ndarray  # half width [m]
    length: np.ndarray  # [m]
    v: np.ndarray  # speed [m/s]


def room_accel(goal, s_vc_front, v_vc, half_w, length, active, others: Around, time_gap,
               min_gap, horizon: float = 0.0) -> float:
    """Acceleration [m/s^2] of the virtual car that keeps every goal slot (n, 2) a time gap
    behind the nearest vehicle in its lane that is ahead of it or beside it (front bumper
    ahead of the slot's rear; gap = its rear minus the slot's front, negative when beside),
    by the governor's constant-time-gap law, bounded below by -ROOM_DECEL; +inf: no such
    vehicle. ``s_vc_front``: the virtual car's arc length plus the CoG-to-front distance [m].
    With ``horizon`` h [s] > 0 the law acts on the situation predicted h on at constant speeds:
    every other vehicle's rear moves by (o_v - v_vc) h relative to the goal slots."""
    o_rear, o_d, o_half_w, o_length, o_v = others
    if not len(o_rear):
        return np.inf
    o_rear = o_rear + (o_v - v_vc) * horizon  # where they will be relative to us
    front = s_vc_front + goal[:, 0]
    rear = front - length
    lane = (np.abs(o_d[None, :] - goal[:, 1][:, None])
            < o_half_w[None, :] + half_w[:, None] + LATERAL_MARGIN)
    cand = lane & ((o_rear + o_length)[None, :] > rear[:, None]) & active[:, None]
    if not cand.any():
        return np.inf
    i, j = np.nonzero(cand)
    gaps = o_rear[j] - front[i]
    a = time_gap_accel(np.maximum(gaps, 0.0), v_vc, o_v[j], time_gap, min_gap)
    return max(float(np.min(a)), -ROOM_DECEL)


class MergeShift:
    """A formation's shift away from a merge lane (``[cooperation] merge = "shift"``,
    docs/maneuvers.md "Ramp traffic"): the merge watch (sumo/merge_watch.py) asks for it at
    the step's sense, :meth:`ManeuverRoadReference.plan` tries it the same step with the
    planner's gap check (:meth:`ManeuverPlanner.merge_shift`)."""

    LANES = 1
    """The shift: one lane to the left (ramps join on the right)."""

    def __init__(self, planner: ManeuverPlanner):
        self.planner = planner
        self.asked = ""  # the watch asks for a shift this step: the ramp vehicle in conflict ("": none)
        self.refused: str | None = None  # why the last attempt was refused (None: none refused)

    @property
    def shifting(self) -> bool:
        """Is the formation's shift under way?"""
        running = self.planner.running
        return running is not None and running[0] == MERGE_SHIFT

    def attempt(self, sn: Situation) -> list[PlannerEvent]:
        """Try the shift asked for (its maneuver_start event; none when refused)."""
        vid, self.asked = self.asked, ""
        ok, detail = self.planner.merge_shift(sn, self.LANES)
        self.refused = None if ok else detail
        return [PlannerEvent("maneuver_start", f"{MERGE_SHIFT}: away from {vid} at the merge, {detail}")] if ok else []


class ManeuverRoadReference(RoadReference):
    """RoadReference whose slots follow the maneuver planner (see the module docstring)."""

    def __init__(self, *args, planner: ManeuverPlanner, length: float, merge_shift: bool = False, **kw):
        super().__init__(*args, **kw)
        self.planner = planner
        self.merge_shift = MergeShift(planner) if merge_shift else None  # [cooperation] merge = "shift"
        self.body_length = np.asarray(length, float)  # [m], one or one per member

    def plan(self, t: float, sensed) -> list[WorldCommand]:
        """The maneuver planner's step: what the world must do now (a leave releases a member,
        a join takes a vehicle over or lets one enter; the maneuver events to record), which
        the loop hands to the world before this step's reference."""
        others = NO_OTHERS
        nb = sensed.nb
        if nb is not None and len(nb.ids):
            others = Others(tuple(nb.ids), sensed.nb_s, sensed.nb_d, nb.length, nb.width, nb.v)
        commands = []
        sn = Situation(float(t), self.s, sensed.m_s, sensed.m_d, sensed.v_m, sensed.active, others, self.v)
        events = self.planner.step(sn)
        if self.merge_shift is not None and self.merge_shift.asked:
            events += self.merge_shift.attempt(sn)
        for ev in events:
            if ev.kind == "release":
                commands.append(WorldCommand("release", ev.member, ev.name))
            elif ev.kind == "take_over":  # the world drops it from sensed.nb
                commands.append(WorldCommand("take_over", ev.member, ev.name))
            elif ev.kind == "enter":
                commands.append(WorldCommand("enter", ev.member, "", ev.where))
            else:
                commands.append(WorldCommand("record", event=ev.kind, detail=ev.detail))
        return commands

    def request_limit(self, t: float, sensed) -> float:
        """The slots of this step (the planner stepped in :meth:`plan`), then the room-making
        deceleration towards the next goal [m/s^2] (:func:`room_accel`; inf when there is no
        goal or nobody near)."""
        now = self.planner.slots(t)
        self.along, self.slot_d = np.ascontiguousarray(now[:, 0]), np.ascontiguousarray(now[:, 1])
        sensed.extra["slot"] = self.planner.slot_of.astype(float)
        p = self.longitudinal.p
        lead = room_lookahead(p.tau, p.jerk_max)
        goal = self.planner.goal_ahead(t, self.s, self.v, sensed.active, lead)
        nb = sensed.nb
        if goal is None or nb is None or not len(nb.ids):
            return super().request_limit(t, sensed)
        lim = self.limits
        room = float(room_accel(goal, self.s + self.d_front, self.v, self.half_w,
                                self.body_length, sensed.active,
                                Around(sensed.nb_rear, sensed.nb_d, sensed.nb_half_w, nb.length,
                                       sensed.nb_v), lim.time_gap, lim.min_gap, lead))
        return min(room, super().request_limit(t, sensed))
