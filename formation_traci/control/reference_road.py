"""Reference generator of road runs: the virtual car along the reference line with the
traffic-aware governor's acceleration (control/governor.py) made jerk-limited by the
longitudinal planner (control/longitudinal.py), slots in road or vehicle frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.kernels import kernel
from ..road.leader import road_leader_at
from .governor import (ACCEL_MAX, DECEL_EMERGENCY, DECEL_FOLLOW, DECEL_MAX, TRAFFIC_AWARE,
                       column_caps, free_road_accel, governor_step)
from .longitudinal import LongitudinalPlanner, PlannerParams, plan_step
from .reference import FRAME_ROAD, FRAME_VEHICLE, Reference, constant_slots, set_vc_period
from .reference_records import MemberPlanner, MemberRows, NeighbourRows, RoadPlan
from .virtual_car import along_line_advance, knot_profile_at


@kernel
def road_vc_rows(G, s, v, a0, a, dt_c, vc):
    """Fill vc (n_ctrl, n, 8) with the virtual car on line G at the start of every control
    period; returns (s, v) at the end of the step. Its acceleration goes from ``a0`` at the
    start of the step to ``a`` at its end at constant jerk (:func:`ramp_advance`: the
    acceleration is continuous from step to step); ``a0 == a``: constant acceleration a
    over the step (``leader.accel_within_step = "hold"`` passes a0 = a)."""
    n_ctrl = vc.shape[0]
    jerk = (a - a0) / (dt_c * n_ctrl)
    for j in range(n_ctrl):
        a_j = a0 + (a - a0) * j / n_ctrl if jerk != 0.0 else a
        X, Y, th, vv, om, vd, omd = road_leader_at(G, s, v, a_j)
        set_vc_period(vc, j, X, Y, th, vv, om, vd, omd, s)
        s, v = ramp_advance(s, v, a_j, jerk, dt_c)
    return s, v


@kernel
def ramp_advance(s, v, a, jerk, dt):
    """Arc length [m] and speed [m/s] after dt [s] from acceleration a [m/s^2] changing at
    ``jerk`` [m/s^3]; jerk 0 (or a stop within dt): :func:`along_line_advance` at constant
    acceleration (the mean over dt for a stop: the car never reverses)."""
    if jerk == 0.0:
        return along_line_advance(s, v, a, dt)
    v1 = v + a * dt + 0.5 * jerk * dt * dt
    if v1 < 0.0:
        return along_line_advance(s, v, a + 0.5 * jerk * dt, dt)
    return s + v * dt + 0.5 * a * dt * dt + jerk * dt * dt * dt / 6.0, v1


@kernel(error_model="python")
def road_reference_step(plan, t, s, v, a_limit, members, nbs, a_vc_prev, has_prev, planner, vc,
                        a_cap_from):
    """One step of the road reference in one compiled call: the governor over the members and
    their neighbours (:func:`governor_step`, :func:`column_caps`; ``plan``:
    control/reference_records.py RoadPlan, slot ``along`` the line ahead of the virtual car
    at ``s`` [m], across it ``slot_d`` [m] for road-frame slots, the member's own offset
    otherwise; ``members``: MemberRows, ``nbs``: NeighbourRows), its request capped by
    ``a_limit`` [m/s^2] (inf: none; a maneuver's room-making deceleration), the jerk-limited
    planner (:func:`plan_step`; members not in the run get no caps) and the virtual car's
    rows into ``vc`` (:func:`road_vc_rows`, control period ``plan.dt_c`` [s]). With
    ``plan.ramp`` the virtual car's acceleration goes from the last step's value
    ``a_vc_prev`` [m/s^2] to this step's within the step and ``a_cap_from`` receives the caps
    of the last step (the members' caps ramp the same way in sim/fleet.py); without, both are
    held over the step. ``nbs.in_formation``, ``nbs.mate_rear``: released members inside the
    formation and the rears of their slots (:func:`governor_step`, :func:`mate_rears`).
    ``plan.lim``: :meth:`GovernorLimits.packed`; ``plan.pp``: :meth:`PlannerParams.packed`.
    The members' acceleration is their mean over the previous step (``planner.v_prev``
    [m/s], updated in place; zero at the first step, ``has_prev`` False). One call instead
    of six.

    Returns (a_request, a_vc, emergency_vc, s_next, v_next, gap, lead_idx, a_cap_request,
    a_cap); ``planner`` (MemberPlanner: a_cap_prev, v_prev, emergency) is updated in place."""
    m_s, m_d, v_m, active = members.s, members.d, members.v, members.active
    d_front, lim, dt_c = plan.d_front, plan.lim, plan.dt_c
    n = m_s.shape[0]
    slot_d = np.empty(n)  # np.where(is_road, slot_d_road, m_d); np.where's numba implementation
    for i in range(n):  # would load numba's arraymath and scipy.linalg at every start (0.3 s)
        slot_d[i] = plan.slot_d[i] if plan.is_road[i] else m_d[i]
    v_set, v_set_dot = knot_profile_at(plan.prof, 0, t)
    slot_s = s + plan.along
    a_gov, gap, lead_idx, v_cap, a_cap_req = governor_step(
        m_s + d_front, m_d, slot_s + d_front, slot_d, plan.half_w, v_m, active, v, v_set,
        v_set_dot, nbs, lim)
    v_cap, a_cap_req = column_caps(slot_s, slot_d, plan.half_w, active, v_cap, a_cap_req)
    a_profile = free_road_accel(v, v_set, v_set_dot, lim[ACCEL_MAX], lim[DECEL_EMERGENCY],
                                lim[DECEL_FOLLOW], lim[DECEL_MAX])  # the set speed's own law
    if lim[TRAFFIC_AWARE] == 0.0:  # not traffic-aware: the free-road law on the profile alone
        a_gov = a_profile
    a_request = a_limit if a_limit < a_gov else a_gov  # Python's min(a_gov, a_limit)
    dt = dt_c * vc.shape[0]
    a_cap_in = a_cap_req.copy()
    for i in range(n):
        if not active[i]:
            v_cap[i] = np.inf
            a_cap_in[i] = np.inf
    a_m = np.zeros(n)
    v_prev, a_cap_prev = planner.v_prev, planner.a_cap_prev
    if has_prev:
        for i in range(n):
            a_m[i] = (v_m[i] - v_prev[i]) / dt
    v_prev[:] = v_m
    a_cap = np.empty(n)
    a_cap_from[:] = a_cap_prev
    a_vc, emergency_vc = plan_step(a_vc_prev, a_request, a_profile, a_cap_prev, v_cap, a_cap_in,
                                   v_m, a_m, dt, plan.pp, a_cap, planner.emergency)
    for i in range(n):
        if not active[i]:  # a cap being eased out goes with its member
            a_cap[i] = np.inf
    a_cap_prev[:] = a_cap
    if not plan.ramp:
        a_cap_from[:] = a_cap
    s_next, v_next = road_vc_rows(plan.G, s, v, a_vc_prev if plan.ramp else a_vc, a_vc, dt_c, vc)
    return a_request, a_vc, emergency_vc, s_next, v_next, gap, lead_idx, a_cap_req, a_cap


_NO_MATES = np.zeros(0)


def mate_rears(inside, nb_rear, nb_length, nb_d, active, slot_front, slot_d, is_road) -> np.ndarray:
    """Rear [m] of the slot each released member inside the formation held, NaN for the
    other neighbours: the slot (front bumper ``slot_front`` [m], across ``slot_d`` [m] for
    road-frame slots) of the member out of the run nearest to the neighbour's front bumper,
    less its length ``nb_length`` [m]. The members behind it keep the formation's spacing to
    it (control/governor.py mate_caps; docs/model.md, "Leave without stranding")."""
    out = np.full(len(nb_rear), np.nan)
    gone = np.flatnonzero(~np.asarray(active, bool))
    if not len(gone):
        return out
    for j in np.flatnonzero(inside):
        front = nb_rear[j] + nb_length[j]
        miss = np.abs(slot_front[gone] - front) + np.where(is_road[gone], np.abs(slot_d[gone] - nb_d[j]), 0.0)
        k = gone[int(np.argmin(miss))]
        out[j] = slot_front[k] - nb_length[j]
    return out


@dataclass(frozen=True)
class GovernorLimits:
    """The governor's settings (scenario [leader], capped by the road's adhesion)."""

    time_gap: float  # [s]
    min_gap: float  # [m]
    accel_max: float  # [m/s^2]
    decel_max: float  # comfortable [m/s^2]
    decel_emergency: float  # [m/s^2]
    decel_follow: float = math.inf
    """Largest braking of the virtual car outside emergencies [m/s^2]: what every member's
    speed loop can follow (sim/setup.py follow_limit; inf: not limiting)."""
    traffic_aware: bool = True
    """False: the virtual car drives its speed profile whatever the traffic ahead of the
    slots and the members do (leader.traffic_aware); the members' own caps still act."""

    def packed(self) -> np.ndarray:
        """(time_gap, min_gap, accel_max, decel_emergency, decel_follow, decel_max,
        traffic_aware 1/0) for :func:`road_reference_step`."""
        return np.array([self.time_gap, self.min_gap, self.accel_max, self.decel_emergency,
                         self.decel_follow, self.decel_max, 1.0 if self.traffic_aware else 0.0])


def end_of_road(t: float, end_margin: float) -> tuple[str, str, str]:
    """The stop of a formation whose front came within ``end_margin`` [m] of its route's end
    at ``t`` [s]: (event kind, detail, why)."""
    return ("end_of_road", f"formation front within {end_margin} m of the route end",
            f"end of the route reached at t = {t:.2f} s")


@dataclass(frozen=True)
class SlotLayout:
    """The members' slots and bodies as a :class:`RoadReference` takes them (n members)."""

    slots: np.ndarray  # (n, 2) road-frame slots: along, across the line [m] (NaN rows: rigid)
    rigid: np.ndarray  # (n, 2) vehicle-frame slots [m] (NaN rows: road-frame)
    is_road: np.ndarray  # (n,) road-frame slot
    half_w: object  # half width [m]: one, or one per member
    d_front: object  # CoG to front bumper [m]: one, or one per member


@dataclass(frozen=True)
class StepTiming:
    """A step's control periods as a :class:`RoadReference` takes them."""

    dt_c: float  # control period [s]
    n_ctrl: int  # control periods per step
    ramp: bool = True  # leader.accel_within_step == "ramp" (docs/model.md)
    release: bool = True  # leader.emergency_release
    jerk_max: float = 0.8  # leader.jerk_max: the planner's jerk outside emergencies [m/s^3]
    jerk_brake: float = 2.0  # leader.jerk_brake: its jerk while firm braking sets in [m/s^3]


class RoadReference:
    """The virtual car of a road run: s [m] and v [m/s] along the line, the governor's
    acceleration per step; ``slots`` / ``rigid`` (n, 2) with NaN rows for the other kind."""

    def __init__(self, G, length: float, layout: "SlotLayout", s0: float, v0: float,
                 speed_profile, limits: GovernorLimits, end_margin: float, timing: "StepTiming"):
        slots, rigid, is_road = layout.slots, layout.rigid, layout.is_road
        half_w, d_front = layout.half_w, layout.d_front
        dt_c, n_ctrl, ramp, release = timing.dt_c, timing.n_ctrl, timing.ramp, timing.release
        self.G, self.length = G, float(length)
        self.is_road = np.asarray(is_road, dtype=bool)
        self.frame = np.where(self.is_road, FRAME_ROAD, FRAME_VEHICLE).astype(np.int64)
        offsets = np.where(self.is_road[:, None], np.nan_to_num(slots), np.nan_to_num(rigid))
        self.slot_d = np.ascontiguousarray(np.nan_to_num(np.asarray(slots, float)[:, 1]))
        self.along = np.ascontiguousarray(offsets[:, 0])  # slot ahead of the virtual car [m]
        self.slots = constant_slots(offsets, n_ctrl)
        self.s, self.v = float(s0), float(v0)
        self.prof = speed_profile.packed()
        # half_w [m], d_front (CoG to front bumper) [m]: one or one per member (a mixed formation)
        n = len(self.frame)
        self.limits = limits
        self.lim = limits.packed()
        self.half_w = np.broadcast_to(np.asarray(half_w, float), (n,)).copy()
        self.d_front = np.broadcast_to(np.asarray(d_front, float), (n,)).copy()
        self.end_margin = float(end_margin)
        self.dt_c, self.n_ctrl = float(dt_c), int(n_ctrl)
        self._next = None
        self.longitudinal = LongitudinalPlanner(len(self.frame), PlannerParams(
            jerk_max=float(timing.jerk_max), jerk_brake=float(timing.jerk_brake),
            decel_comfort=limits.decel_max,
            jerk_release=PlannerParams.jerk_release if release else 0.0))
        self._v_prev = np.zeros(len(self.frame))  # members' speed at the previous step [m/s]
        self._has_prev = False
        self.ramp = bool(ramp)  # leader.accel_within_step == "ramp" (docs/model.md)

    @property
    def road_plan(self) -> RoadPlan:
        """The reference's fixed data as :func:`road_reference_step` takes it."""
        return RoadPlan(self.G, self.prof, self.along, self.slot_d, self.is_road, self.d_front,
                        self.half_w, self.lim, self.longitudinal.pp, self.dt_c, self.ramp)

    @property
    def v_prev(self) -> np.ndarray:
        """The members' speeds at the previous step [m/s] (updated in place every step)."""
        return self._v_prev

    @property
    def has_prev(self) -> bool:
        """A previous step's :attr:`v_prev` exists."""
        return self._has_prev

    @has_prev.setter
    def has_prev(self, value: bool) -> None:
        self._has_prev = bool(value)

    def plan(self, t: float, sensed) -> list:
        """What the world must do before this step's reference (control/reference.py
        WorldCommand): nothing without maneuvers."""
        return []

    def request_limit(self, t: float, sensed) -> float:
        """An upper bound on the virtual car's requested acceleration [m/s^2] for the step
        starting at t [s] (inf: none): the world's (``sensed.a_limit``: ramp traffic); a
        maneuver's generator bounds it further and moves the slots."""
        return sensed.a_limit

    def reference(self, t: float, sensed) -> Reference:
        """The reference of the step starting at t [s] (:func:`road_reference_step`)."""
        a_limit = self.request_limit(t, sensed)
        pl = self.longitudinal
        vc = np.empty((self.n_ctrl, len(self.frame), 8))
        a_cap_from = np.empty(len(self.frame))
        (a_request, pl.a_vc, pl.emergency_vc, s_next, v_next, gap, lead_idx, a_cap_req,
         a_cap) = road_reference_step(
            self.road_plan, float(t), self.s, self.v, a_limit,
            MemberRows(sensed.m_s, sensed.m_d, sensed.v_m, sensed.active),
            NeighbourRows(sensed.nb_rear, sensed.nb_d, sensed.nb_half_w, sensed.nb_v,
                          sensed.nb_in_formation, self.mate_rears(sensed)),
            pl.a_vc, self._has_prev, MemberPlanner(pl.a_cap, self._v_prev, pl.emergency), vc,
            a_cap_from)
        self._has_prev = True
        self._next = (s_next, v_next)
        truth = vc[0, 0].copy()  # period 0: road_leader_at(G, s, v, a_vc) and s
        return Reference(float(t), self.dt_c, vc, self.slots, self.frame, sensed.active, pl.v_cap,
                         a_cap, line=self.G, truth=truth,
                         a_cap_from=a_cap_from if self.ramp else None,
                         info={"a_vc": pl.a_vc, "gap": gap, "lead_idx": lead_idx,
                               "a_request": a_request, "a_cap_request": a_cap_req,
                               "emergency": pl.emergency_vc,
                               "emergency_members": pl.emergency.copy()})

    def mate_rears(self, sensed) -> np.ndarray:
        """:func:`mate_rears` of this step's slots (empty when no released member is inside
        the formation)."""
        inside = sensed.nb_in_formation
        if not inside.any():
            return _NO_MATES
        return mate_rears(inside, sensed.nb_rear, sensed.nb.length, sensed.nb_d, sensed.active,
                          self.s + self.along + self.d_front, self.slot_d, self.is_road)

    def commit(self) -> None:
        self.s, self.v = (float(q) for q in self._next)

    def parked(self, t: float) -> Reference:
        """The reference while the formation waits to depart or after it left its route: the
        virtual car standing at its s, no member in the run, no virtual-car row (truth NaN);
        the same keys of ``info`` as :meth:`reference` (sim/formation.py join_info)."""
        got = getattr(self, "_parked", None)
        if got is None or got[0] != self.s:
            n = len(self.frame)
            vc = np.empty((self.n_ctrl, n, 8))
            road_vc_rows(self.G, self.s, 0.0, 0.0, 0.0, self.dt_c, vc)
            no = np.full(n, np.inf)
            ref = Reference(float(t), self.dt_c, vc, self.slots, self.frame, np.zeros(n, dtype=bool),
                            no, no, line=self.G, truth=np.full(8, np.nan),
                            info={"a_vc": 0.0, "gap": np.full(n, np.inf), "lead_idx": np.full(n, -1),
                                  "a_request": 0.0, "a_cap_request": np.zeros(n), "emergency": False,
                                  "emergency_members": np.zeros(n, dtype=bool)})
            got = self._parked = (self.s, ref)
        return got[1].with_(t=float(t))

    @property
    def reach(self) -> float:
        """How far ahead of the virtual car [m] the run stops: the formation's front plus
        ``end_margin``."""
        return float(np.max(self.along + self.d_front)) + self.end_margin

    def stop_reason(self, t: float):
        """('end_of_road', message) when the formation's front nears the route's end."""
        return end_of_road(t, self.end_margin) if self.s + self.reach > self.length else None
