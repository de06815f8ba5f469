"""Many formations at the cost of one: the formations of a road run whose reference is a plain
road reference (control/reference_road.py RoadReference: no maneuvers, no transforms such as
a radio) stepped together, one compiled call for all of them (control/reference_group.py)
and no Python work per formation and step.

The loop (sim/loop.py) uses a :class:`FormationGroup` instead of its per-formation path when
every formation of a run of several on a road is such a formation (:func:`group_of`); the
results are those of the per-formation path, bit for bit (the golden of
scenarios/highway/three_formations.toml, recorded with the per-formation path, pins it).
Departures, a flow's room check and a retirement at the end of the route stay per formation
(sim/formation.py depart_due, retire_formation): they happen once per formation, not per step;
per step the group reads its own arrays (status, departure time, the parked rows' held state).
"""
from __future__ import annotations

import numpy as np

from ..control.reference import Reference
from ..control.reference_group import group_reference_step
from ..control.reference_records import (GroupPlan, MemberRows, NeighbourRows, PlannerState,
                                         ReferenceOut)
from ..control.reference_road import RoadReference, end_of_road
from .fleet_state import FleetState
from .formation import depart_due, enters, retire_formation

WAITING, RUNNING, DONE = 0, 1, 2
_CODE = {"waiting": WAITING, "running": RUNNING, "done": DONE}

_NO_MATES = np.empty(0)
_NO_TABLE = (np.empty(0), np.empty(0), np.empty(0), np.empty(0), np.zeros(0, dtype=np.bool_),
             np.empty(0, dtype=np.int64))


def group_of(forms: list, world) -> "FormationGroup | None":
    """The group of ``forms`` when all of them (two or more) are plain road formations and the
    world can join their neighbours (SUMO); else None (the loop's per-formation path)."""
    if len(forms) < 2 or not hasattr(world, "joined_neighbours"):
        return None
    if any(type(f.generator) is not RoadReference or f.transforms for f in forms):
        return None
    return FormationGroup(forms)


class FormationGroup:
    """The state of every formation's road reference as arrays (see the module docstring)."""

    def __init__(self, forms: list):
        gens = [f.generator for f in forms]
        self.forms, g0 = forms, gens[0]
        self.G, self.dt_c, self.n_ctrl, self.length = g0.G, g0.dt_c, g0.n_ctrl, g0.length
        self.starts = np.array([f.members.start for f in forms] + [forms[-1].members.stop], dtype=np.int64)
        self.profs = np.concatenate([g.prof for g in gens])
        self.prof_at = np.cumsum([0] + [len(g.prof) for g in gens]).astype(np.int64)
        cat = (lambda get: np.ascontiguousarray(np.concatenate([get(g) for g in gens])))  # noqa: E731
        self.along, self.slot_d = cat(lambda g: g.along), cat(lambda g: g.slot_d)
        self.is_road, self.d_front, self.half_w = cat(lambda g: g.is_road), cat(lambda g: g.d_front), cat(lambda g: g.half_w)
        self.frame, self.slots = cat(lambda g: g.frame), np.concatenate([g.slots for g in gens], axis=1)
        self.lims = np.stack([g.lim for g in gens])
        self.pps = np.stack([g.longitudinal.pp for g in gens])
        self.ramps = np.array([g.ramp for g in gens])
        self.s, self.v = np.array([g.s for g in gens]), np.array([g.v for g in gens])
        self.a_vc = np.array([g.longitudinal.a_vc for g in gens])
        self.emergency_vc = np.zeros(len(gens), dtype=np.bool_)
        self.a_cap_prev = cat(lambda g: g.longitudinal.a_cap)
        self.v_prev, self.emergency = cat(lambda g: g.v_prev), cat(lambda g: g.longitudinal.emergency)
        self.has_prev = np.zeros(len(gens), dtype=np.bool_)
        self.reach = np.array([g.reach for g in gens])
        self.end_margin = np.array([g.end_margin for g in gens])
        self._next = None
        self.status = np.array([_CODE[f.status] for f in forms], dtype=np.int8)
        self.depart = np.array([f.depart for f in forms], dtype=float)
        self.counts = np.diff(self.starts)
        self._held = None  # every row's held state (a parked formation's rows), at the first settle

    @property
    def plan(self) -> GroupPlan:
        """The formations' fixed reference data as the compiled references take them."""
        return GroupPlan(self.G, self.profs, self.prof_at, self.along, self.slot_d, self.is_road,
                         self.d_front, self.half_w, self.starts, self.lims, self.pps, self.ramps,
                         self.frame, self.slots, self.depart)

    @property
    def planner(self) -> PlannerState:
        """The references' planner state (updated in place by the compiled references)."""
        return PlannerState(self.a_vc, self.emergency_vc, self.has_prev, self.a_cap_prev,
                            self.v_prev, self.emergency)

    @property
    def held_state(self):
        """Every row's held state (sim/fleet_state.py FleetState; a parked formation's rows),
        None before the first :meth:`settle`."""
        return self._held

    def _sync(self, i: int) -> None:
        """Formation i's status and departure time after depart_due or retire_formation."""
        f = self.forms[i]
        self.status[i], self.depart[i] = _CODE[f.status], f.depart
        if f.status == "done" and self._held is not None:
            self._held.hold(f.members, f.held)

    def any_enters(self, world, t: float, state: FleetState) -> bool:
        """Does a formation due at t [s] enter now (sim/formation.py ``enters``; nothing
        changes)? Those of a flow without room wait: a step where none enters is a usual one
        for the others (sumo/fused_refs.py)."""
        blocked: set = set()
        return any(enters(self.forms[i], world, t, state, blocked)
                   for i in np.flatnonzero((self.status == WAITING) & (t >= self.depart - 1e-9)))

    def references(self, world, k: int, t: float, sensed, state: FleetState):
        """The joined Reference of the step starting at t [s] (the loop's (raw, reference,
        error reference): all three the same, a group has no transforms)."""
        blocked: set = set()
        for i in np.flatnonzero((self.status == WAITING) & (t >= self.depart - 1e-9)):
            depart_due(self.forms[i], world, t, state, blocked)
            self._sync(i)
        run = self.status == RUNNING
        nb_rear, nb_d, nb_half_w, nb_v, nb_in_f, owner = (
            _NO_TABLE if sensed.nb is None else world.joined_neighbours(sensed))
        n, k_f = len(self.frame), len(self.forms)
        vc, truth = np.empty((self.n_ctrl, n, 8)), np.empty((k_f, 8))
        a_cap_from, gap, a_cap_req, a_cap = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        lead_idx = np.empty(n, dtype=np.int64)
        a_request, s_next, v_next = np.empty(k_f), np.empty(k_f), np.empty(k_f)
        t_f = t - self.depart
        group_reference_step(
            self.plan, self.planner,
            ReferenceOut(vc, a_cap_from, a_request, s_next, v_next, gap, lead_idx, a_cap_req,
                         a_cap, truth),
            t_f, self.s, self.v, run, np.full(k_f, np.inf) if sensed.a_limits is None else sensed.a_limits,
            MemberRows(sensed.m_s, sensed.m_d, sensed.v_m, sensed.active),
            NeighbourRows(nb_rear, nb_d, nb_half_w, nb_v, nb_in_f, _NO_MATES), owner, self.dt_c)
        self._next = (run, s_next, v_next)
        rows = np.repeat(run, np.diff(self.starts))
        n_nb = None if sensed.nb is None else len(sensed.nb.ids)
        info = {"a_vc": np.where(run, self.a_vc, 0.0), "gap": gap,
                "lead_idx": lead_idx if n_nb is None else np.where(lead_idx >= n_nb, -1, lead_idx),
                "a_request": a_request, "a_cap_request": a_cap_req,
                "emergency": run & self.emergency_vc, "emergency_members": rows & self.emergency}
        ramp = bool(self.ramps.any())
        ref = Reference(float(t), self.dt_c, vc, self.slots, self.frame, sensed.active,
                        np.full(n, np.inf), a_cap, line=self.G, truth=truth,
                        a_cap_from=a_cap_from if ramp else None, info=info)
        return ref, ref, ref

    def settle(self, state: FleetState) -> None:
        """After the members' step: the running formations' virtual cars move to the step's
        end; the members of the others are held."""
        run, s_next, v_next = self._next
        self.s, self.v = np.where(run, s_next, self.s), np.where(run, v_next, self.v)
        parked = self.status != RUNNING
        if not parked.any():
            return
        if self._held is None:
            self._held = state.copy()
            if self._held.u_last is None:  # FleetState.hold: zeros where a held state has none
                self._held.u_last = np.zeros(len(state.theta_star))
            for i in np.flatnonzero(parked):
                self._held.hold(self.forms[i].members, self.forms[i].held)
        state.hold_where(np.repeat(parked, self.counts), self._held)

    def stop(self, world, t: float, state: FleetState, rec, active=None) -> bool:
        """Retire every running formation whose front nears the end of its route; True when
        every formation is done."""
        for i in np.flatnonzero((self.status == RUNNING) & (self.s + self.reach > self.length)):
            retire_formation(self.forms[i], world, t, state, rec, end_of_road(t, self.end_margin[i]), active)
            self._sync(i)
        return bool((self.status == DONE).all())
