"""The reference state the compiled step (sumo/fused_step.py) works on, for the two kinds of
plain road runs: one formation (control/reference_road.py RoadReference, its scalars as
arrays of one formation, written back after every step) and several formations
(sim/formation_group.py FormationGroup, whose arrays the compiled step updates in place).
Both give the compiled step control/reference_group.py group_reference_step's arrays, so
one compiled step serves both (sumo/fused_path.py)."""
from __future__ import annotations

import numpy as np

from ..control.reference_records import GroupPlan, PlannerState
from ..sim.formation_group import RUNNING



def _bodies(ref_d_front, world) -> np.ndarray:
    """(4, n): CoG to front bumper as the reference takes it, and length, width and CoG to
    front bumper of the members' SUMO types [m] (sumo/peers.py)."""
    return np.array([ref_d_front, [mt.length for mt in world.mtypes],
                     [mt.width for mt in world.mtypes], world.d_front], dtype=float)


class OneFormation:
    """One formation's RoadReference as the compiled step's arrays of one formation."""

    vc_key = None  # EmergencyWatch's 'emergency': the planner's flag itself

    running = np.ones(1, dtype=np.bool_)
    vc_rows = 1

    def __init__(self, gen, world):
        self.gen, self.pl = gen, gen.longitudinal
        self.parked = np.zeros(len(gen.frame), dtype=np.bool_)
        self.reach = gen.reach  # fixed for a run: the formation's front plus the end margin [m]
        self.s, self.v, self.a_vc = np.empty(1), np.empty(1), np.empty(1)
        self.em_vc, self.has_prev = np.zeros(1, dtype=np.bool_), np.zeros(1, dtype=np.bool_)
        pl = self.pl
        self.plan = GroupPlan(gen.G, gen.prof, np.array([0, len(gen.prof)], dtype=np.int64),
                              gen.along, gen.slot_d, gen.is_road, gen.d_front, gen.half_w,
                              np.array([0, len(gen.frame)], dtype=np.int64), gen.lim[None, :],
                              pl.pp[None, :], np.array([gen.ramp]), gen.frame, gen.slots,
                              np.zeros(1))
        self.bodies, self.peers = _bodies(gen.d_front, world), False
        self.planner = PlannerState(self.a_vc, self.em_vc, self.has_prev, pl.a_cap, gen.v_prev,
                                    pl.emergency)
        self._kept = (pl.a_cap, gen.v_prev, pl.emergency)

    def held(self, state):
        """The held state's arrays (no member of one formation is ever parked: any rows)."""
        return state.x, state.theta_star, state.speed_in, state.theta_star

    def enters(self, t: float, state) -> bool:
        """One formation running from t = 0: none enters."""
        return False

    def usual(self, t: float) -> bool:
        """Not at the end of its route, and the arrays given to the compiled step are the
        reference's still."""
        gen, pl = self.gen, self.pl
        a_cap, v_prev, emergency = self._kept
        return (gen.s + self.reach <= gen.length and pl.a_cap is a_cap and gen.v_prev is v_prev
                and pl.emergency is emergency)

    def before(self):
        """The step's (s, v) [m, m/s]; the planner's scalars into their arrays."""
        gen, pl = self.gen, self.pl
        self.s[0], self.v[0], self.a_vc[0] = gen.s, gen.v, pl.a_vc
        self.em_vc[0], self.has_prev[0] = pl.emergency_vc, gen.has_prev
        return self.s, self.v

    def after(self) -> None:
        """The planner's scalars back from their arrays (RoadReference.reference's)."""
        self.gen.has_prev, self.pl.a_vc = True, float(self.a_vc[0])
        self.pl.emergency_vc = bool(self.em_vc[0])

    def emergency_info(self, a_request, a_cap_req) -> dict:
        """What sumo/events.py EmergencyWatch reads of the step (RoadReference.reference's
        Reference.info)."""
        return {"emergency_members": self.pl.emergency.copy(), "emergency": self.pl.emergency_vc,
                "a_request": float(a_request[0]), "a_cap_request": a_cap_req}

    def settle(self, s_next, v_next) -> None:
        """The virtual car at the step's end (RoadReference.commit)."""
        self.gen.s, self.gen.v = float(s_next[0]), float(v_next[0])


class GroupOfFormations:
    """Several formations' FormationGroup: its arrays are the compiled step's."""

    def __init__(self, group, world):
        g = self.group = group
        self.world = world
        self.reach = g.reach
        self.running, self.parked, self.vc_rows = g.status == RUNNING, None, 0
        self.plan, self.planner = g.plan, g.planner
        self.bodies, self.peers = _bodies(g.d_front, world), True
        self._kept = (g.a_vc, g.emergency_vc, g.has_prev, g.a_cap_prev, g.v_prev, g.emergency,
                      g.depart)

    def usual(self, t: float) -> bool:
        """No formation nears the end of its route at t [s] (FormationGroup.stop), the parked
        rows' held state exists (the first FormationGroup.settle keeps it), the arrays given
        to the compiled step are the group's still; sets :attr:`running`, :attr:`parked` and
        :attr:`vc_rows` (:meth:`enters` asks the rest)."""
        g = self.group
        run = g.status == RUNNING
        if ((run & (g.s + self.reach > g.length)).any()
                or not all(a is b for a, b in zip(self._kept, (g.a_vc, g.emergency_vc, g.has_prev,
                                                               g.a_cap_prev, g.v_prev, g.emergency,
                                                               g.depart)))):
            return False
        self.running, self.vc_rows = run, int(run.sum())
        self.parked = np.repeat(~run, g.counts)
        return g.held_state is not None or not self.parked.any()

    def enters(self, t: float, state) -> bool:
        """Does a formation due at t [s] enter now (FormationGroup.any_enters; ``state``: the
        members' state at t)? One of a flow that is due but finds no room waits, and the step
        stays a usual one for the others."""
        return self.group.any_enters(self.world, t, state)

    def held(self, state):
        """The parked rows' held state (FormationGroup.settle's; the state itself when none)."""
        h = self.group.held_state
        if h is None:  # nothing parked: any rows
            return state.x, state.theta_star, state.speed_in, state.theta_star
        return h.x, h.theta_star, h.speed_in, h.u_last

    def before(self):
        return self.group.s, self.group.v

    def after(self) -> None:
        pass

    def emergency_info(self, a_request, a_cap_req) -> dict:
        """FormationGroup.references' Reference.info."""
        g = self.group
        return {"emergency_members": ~self.parked & g.emergency,
                "emergency": self.running & g.emergency_vc, "a_request": a_request.copy(),
                "a_cap_request": a_cap_req}

    def settle(self, s_next, v_next) -> None:
        """FormationGroup.settle's virtual cars (the parked rows are held in the compiled step)."""
        g = self.group
        g.s, g.v = np.where(self.running, s_next, g.s), np.where(self.running, v_next, g.v)
