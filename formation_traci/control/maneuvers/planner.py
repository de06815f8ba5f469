"""The maneuver planner: the scenario's schedule -> a slot plan, step by step.

Once per SUMO step the planner looks at what was sensed (virtual car, members, the vehicles
around them in road coordinates) and returns the events of the step. Maneuvers run one at a
time in the order listed. A due maneuver starts when its target slots are on the road and
(``check_gaps``) its target lanes have room; otherwise it is postponed (one
``maneuver_postponed`` event with the reason) and retried every step until ``timeout``
seconds after it became due, then given up (``maneuver_cancelled``). A started maneuver
writes the transition of every active member into :attr:`plan` (transition.py), which the
step kernels evaluate at every control period with its exact derivatives.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...road.lanes import LaneCentres
from .assign import assign_slots, min_clearance
from .gap import GapMargins, Others, check_gaps
from .join import describe, join_duration, path_clearance, pick_vehicle, without
from .transition import ComfortLimits, hold_plan, slots_at, transition_duration
from .triggers import is_due, queue_behind


@dataclass(frozen=True, slots=True)
class Situation:
    """What the planner sees at the start of a step (road coordinates)."""

    t: float  # formation time [s]
    s_vc: float  # virtual car's arc length [m]
    m_s: np.ndarray  # (n,) members' centre arc length [m]
    m_d: np.ndarray  # (n,) members' lateral offset [m]
    v_m: np.ndarray  # (n,) members' speed [m/s]
    active: np.ndarray  # (n,) bool
    others: Others
    v_vc: float = 0.0  # virtual car's speed [m/s]


@dataclass(frozen=True, slots=True)
class PlannerEvent:
    kind: str  # maneuver_start | maneuver_end | maneuver_postponed | maneuver_cancelled | release | take_over
    detail: str  # "<maneuver>: ..." (the maneuver's name first)
    member: int = -1  # release / take_over: the member handed over to or taken from the world
    name: str = ""  # release: the exit edge ("" = stay on the route); take_over: the vehicle
    where: tuple = ()  # enter: (s [m], d [m], v [m/s]) where and how fast the member's vehicle enters


MERGE_SHIFT = "merge_shift"
"""The name of a whole-formation lane change away from a merge lane ([cooperation] merge =
'shift': :meth:`ManeuverPlanner.merge_shift`), in its maneuver_start / maneuver_end events."""


@dataclass(frozen=True, slots=True)
class _LaneChange:
    """A lane change of the whole formation asked for outside the schedule (as a ManeuverSpec)."""

    kind: str
    lanes: int
    check_gaps: bool = True


RoomFn = Callable[[float, float], tuple[float, float]]
"""room(s0, s1) -> (d_min, d_max): the road's lateral extent over [s0, s1] [m]."""


def limits_from_spec(spec) -> ComfortLimits:
    """ComfortLimits from a scenario.maneuvers.ManeuverLimits."""
    return ComfortLimits(spec.lat_accel, spec.lat_jerk, spec.lon_accel, spec.lon_jerk,
                         spec.min_duration)


class ManeuverPlanner:
    """Holds the slot plan (n, 6), the formation's shape (m, 2) and who holds which slot."""

    def __init__(self, specs, slots0: np.ndarray, lanes: LaneCentres | float, limits_spec,
                 lengths, widths, ids, room: RoomFn | None = None,
                 follow: tuple[float, float] = (0.0, 0.0), d_front=None):
        """``lanes``: the road's lane centres (sumo/road_setup.py Road.lanes), or a lane width
        [m] for uniform lanes (no network)."""
        self.specs = list(specs)
        self.plan = hold_plan(slots0)
        self.shape = np.array(slots0, dtype=float)
        self.slot_of = np.arange(len(slots0))
        self.lanes = lanes if isinstance(lanes, LaneCentres) else LaneCentres.uniform(lanes)
        self.limits = limits_from_spec(limits_spec)
        self.gap_time, self.gap_min = limits_spec.gap_time, limits_spec.gap_min
        # towards vehicles ahead: at least the governor's (time gap [s], standstill gap [m])
        self.ahead = (max(self.gap_time, follow[0]), max(self.gap_min, follow[1]))
        self.lengths = np.broadcast_to(np.asarray(lengths, float), (len(slots0),))
        self.widths = np.broadcast_to(np.asarray(widths, float), (len(slots0),))
        self.ids = list(ids)
        # CoG to front bumper [m]: where a vehicle taken over has its CoG (join)
        self.d_front = np.broadcast_to(np.asarray(self.lengths / 2 if d_front is None else d_front,
                                                  float), (len(slots0),))
        self.room = room
        self.next = 0
        self.running: tuple[str, float] | None = None  # (name, end time [s])
        self.due_since: float | None = None
        self.postponed = False
        self.intervals: list[tuple[str, float, float]] = []
        self.pending_goal: np.ndarray | None = None  # goal of the due maneuver while postponed
        self.entered = -1  # index of the join whose member's vehicle has entered the road

    def goal(self) -> np.ndarray | None:
        """Slots (n, 2) the formation is moving to or waiting to move to (None: holding):
        the governor keeps room ahead of them as well as of the present slots."""
        if self.running is not None:
            return self.plan[:, 2:4]
        if self.due_since is not None:
            return self.pending_goal
        return None

    def goal_ahead(self, t: float, s_vc: float, v_vc: float, active, lead: float) -> np.ndarray | None:
        """:meth:`goal`, or the goal slots (n, 2) of the next reshape or lane change when its
        time or position trigger is predicted to fire within ``lead`` [s] (the virtual car at
        s_vc [m] driving on at v_vc [m/s]; ``active`` (n,) members); None otherwise (a queue
        trigger is not foreseen)."""
        goal = self.goal()
        if goal is not None or self.running is not None or self.next >= len(self.specs):
            return goal
        spec = self.specs[self.next]
        at = spec.at
        soon = ((at.time is not None and at.time - t <= lead)
                or (at.s is not None and at.s - s_vc <= max(v_vc, 0.0) * lead))
        if not soon or spec.kind not in ("reshape", "lane_change"):
            return None
        active = np.asarray(active, dtype=bool)
        shape, slot_of = self._target(spec, active, s_vc)
        goal = self.plan[:, 2:4].copy()
        goal[active] = shape[slot_of[active]]
        return goal

    @property
    def idle(self) -> bool:
        return self.running is None and self.next >= len(self.specs)

    def slots(self, t: float) -> np.ndarray:
        """Members' slots (n, 2) at time t [s]."""
        return slots_at(self.plan, t)[0]

    def step(self, sn: Situation) -> list[PlannerEvent]:
        events: list[PlannerEvent] = []
        if self.running is not None:
            name, t_end = self.running
            if sn.t < t_end - 1e-9:
                return events
            events.append(PlannerEvent("maneuver_end", name))
            self.running = None
        while self.next < len(self.specs):
            spec = self.specs[self.next]
            if self.due_since is None:
                q = 0
                if spec.at.queue_behind is not None:
                    a = sn.active
                    q = queue_behind(sn.m_s[a], sn.m_d[a], self.lengths[a], self.lanes,
                                     sn.others, spec.at.queue_reach)
                if not is_due(spec.at, sn.t, sn.s_vc, q):
                    break
                self.due_since = sn.t
            if spec.kind == "leave":
                events += self._leave(spec, sn)
                self._advance()
                continue
            if spec.kind == "join":
                ok, detail, take = self._try_join(spec, sn)
            else:
                (ok, detail), take = self._try_start(spec, sn), []
            events += take
            if ok:
                events.append(PlannerEvent("maneuver_start", f"{spec.kind}: {detail}"))
                self._advance()
                break
            if sn.t - self.due_since >= spec.timeout - 1e-9:
                events.append(PlannerEvent("maneuver_cancelled",
                                           f"{spec.kind}: timed out after {spec.timeout:g} s: {detail}"))
                self._advance()
                continue
            if not self.postponed:
                events.append(PlannerEvent("maneuver_postponed", f"{spec.kind}: {detail}"))
                self.postponed = True
            break
        return events

    def merge_shift(self, sn: Situation, lanes: int = 1) -> tuple[bool, str]:
        """Move the whole formation ``lanes`` lanes (left positive) now, as a scheduled
        lane change with ``check_gaps`` would start (room on the road, gap check, comfort-limited
        transition; events maneuver_start / maneuver_end named MERGE_SHIFT, the caller records
        the start): (started, detail or why not). Not while a maneuver runs or is due."""
        if self.running is not None:
            return False, f"the maneuver {self.running[0]!r} is under way"
        if self.due_since is not None:
            return False, "a scheduled maneuver is due"
        pending = self.pending_goal
        ok, detail = self._try_start(_LaneChange(MERGE_SHIFT, lanes), sn)
        self.pending_goal = pending  # a refused shift leaves no goal behind
        return ok, detail

    def _leave(self, spec, sn: Situation) -> list[PlannerEvent]:
        """A leave: the member is released at once (a following reshape may close its slot)."""
        i = self.ids.index(spec.member)
        if not sn.active[i]:
            return [PlannerEvent("maneuver_cancelled", f"leave: member {spec.member!r} is no longer in the run")]
        self.intervals.append(("leave", sn.t, sn.t))
        way = f" by the exit {spec.exit!r}" if spec.exit else ""
        return [PlannerEvent("maneuver_start", f"leave: member {spec.member!r}{way}"),
                PlannerEvent("release", f"leave: member {spec.member!r}", i, spec.exit or ""),
                PlannerEvent("maneuver_end", "leave")]

    def _try_join(self, spec, sn: Situation) -> tuple[bool, str, list[PlannerEvent]]:
        """A join: take over the vehicle join.pick_vehicle finds near the member's free slot
        and start its slot where it is (join.py); wait while none is within reach or its path
        into the slot has no room."""
        i = self.ids.index(spec.member)
        if sn.active[i]:
            return False, f"member {spec.member!r} is already in the formation", []
        goal = self.plan[i, 2:4].copy()
        o = sn.others
        if spec.enter is not None and self.entered != self.next:
            return self._enter(spec, i, sn)
        vehicle = spec.member if spec.enter is not None else spec.vehicle
        j = pick_vehicle(o, sn.s_vc + goal[0], goal[1], spec.reach, self.lanes,
                         float(self.lengths[i]), float(self.widths[i]), vehicle)
        if j < 0:
            return False, f"no vehicle within {spec.reach:g} m of the free slot of {spec.member!r}", []
        start = np.array([o.s[j] + o.length[j] / 2 - self.d_front[i] - sn.s_vc, o.d[j]])
        r0 = float(o.v[j] - sn.v_vc)
        T = join_duration(goal[0] - start[0], goal[1] - start[1], r0, 0.0, self.limits)
        a = sn.active
        rest = without(o, j)
        if spec.check_gaps:
            verdict = check_gaps(np.array([o.s[j]]), np.array([goal[0] - start[0]]),
                                 np.array([o.d[j]]), np.array([goal[1]]), self.lengths[[i]],
                                 self.widths[[i]], np.array([sn.v_vc]), rest, T,
                                 GapMargins(self.gap_time, self.gap_min, *self.ahead),
                                 [spec.member])
            if not verdict.ok:
                return False, f"no room: {verdict.reason}", []
        clear = path_clearance(start, goal, r0 * T, self.plan[a, 2:4], float(self.lengths[i]),
                               float(self.widths[i]), self.lengths[a], self.widths[a])
        if clear < 0.0:
            return False, f"its path into the slot crosses a member ({clear:.2f} m)", []
        self.plan[i] = [*start, *goal, sn.t, T, r0, 0.0]
        self.running = ("join", sn.t + T)
        self.intervals.append(("join", sn.t, sn.t + T))
        gap = float(np.hypot(*(goal - start)))
        return True, f"member {spec.member!r} {describe(o.ids[j], gap, T, r0)}", [
            PlannerEvent("take_over", f"join: {o.ids[j]}", i, o.ids[j])]

    def _enter(self, spec, i: int, sn: Situation) -> tuple[bool, str, list[PlannerEvent]]:
        """The joining member's own vehicle enters the road under SUMO's driver at
        ``spec.enter`` from the virtual car, at its speed, once no vehicle in that lane is
        closer than the bodies plus gap_min + gap_time v."""
        e = spec.enter
        s = sn.s_vc + e.along
        d = e.across if e.across is not None else float(self.lanes.across(e.lanes, s))
        o = sn.others
        need = ((self.lengths[i] + o.length) / 2 + self.gap_min
                + self.gap_time * np.maximum(o.v, sn.v_vc))
        close = self.lanes.same_lane(s, o.d, d) & (np.abs(o.s - s) < need)
        if close.any():
            k = int(np.flatnonzero(close)[0])
            return False, (f"the entry of {spec.member!r} is blocked by {o.ids[k]} "
                           f"({o.s[k] - s:+.1f} m from it)"), []
        self.entered = self.next
        return False, (f"{spec.member!r} entered under SUMO's driver, waiting for it to come "
                       f"within {spec.reach:g} m of the free slot"), [
            PlannerEvent("enter", f"join: {spec.member}", i, "", (s, d, sn.v_vc))]

    def _advance(self):
        self.next += 1
        self.due_since = None
        self.postponed = False
        self.pending_goal = None

    def _target(self, spec, active, s_vc: float):
        """New shape (m, 2), and each active member's slot index in it, the virtual car at
        arc length s_vc [m]: lanes are SUMO's lane centres on the edge where each slot is
        (road/lanes.py LaneCentres)."""
        held = self.plan[:, 2:4]
        if spec.kind in ("lane_change", MERGE_SHIFT):
            shape = self.shape.copy()
            shape[:, 1] = self.lanes.shift(s_vc + shape[:, 0], shape[:, 1], spec.lanes)
            return shape, self.slot_of.copy()
        shape = np.array([[s.along, s.across if s.across is not None
                           else float(self.lanes.across(s.lanes, s_vc + s.along))]
                          for s in spec.slots], dtype=float)
        slot_of = self.slot_of.copy()
        idx = np.flatnonzero(active)
        slot_of[idx] = assign_slots(held[idx], shape)
        return shape, slot_of

    def _try_start(self, spec, sn: Situation) -> tuple[bool, str]:
        a = sn.active
        shape, slot_of = self._target(spec, a, sn.s_vc)
        start = self.plan[:, 2:4].copy()
        goal = start.copy()
        goal[a] = shape[slot_of[a]]
        T = transition_duration(goal[a, 0] - start[a, 0], goal[a, 1] - start[a, 1], self.limits)
        self.pending_goal = goal
        v = float(np.max(sn.v_m[a], initial=0.0))
        if self.room is not None:
            s_lo = sn.s_vc + float(np.min(goal[a, 0]))
            d_min, d_max = self.room(s_lo, s_lo + v * T + float(np.ptp(goal[a, 0])) + 50.0)
            half = self.widths[a] / 2
            if np.any(goal[a, 1] - half < d_min - 1e-6) or np.any(goal[a, 1] + half > d_max + 1e-6):
                return False, "target slots off the road ahead"
        if spec.check_gaps:
            ai = np.flatnonzero(a)
            verdict = check_gaps(sn.m_s[ai], goal[ai, 0] - start[ai, 0], sn.m_d[ai], goal[ai, 1],
                                 self.lengths[ai], self.widths[ai], sn.v_m[ai], sn.others, T,
                                 GapMargins(self.gap_time, self.gap_min, *self.ahead),
                                 [self.ids[i] for i in ai])
            if not verdict.ok:
                return False, f"no room: {verdict.reason}"
        clear = min_clearance(start[a], goal[a], self.lengths[a], self.widths[a])
        self.plan[:, 0:2] = start
        self.plan[:, 2:4] = goal
        self.plan[:, 4] = sn.t
        self.plan[:, 5] = T
        self.plan[:, 6:8] = 0.0
        self.shape, self.slot_of = shape, slot_of
        self.running = (spec.kind, sn.t + T)
        self.intervals.append((spec.kind, sn.t, sn.t + T))
        return True, f"T = {T:.2f} s, min clearance {clear:.2f} m"
