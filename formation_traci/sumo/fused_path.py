"""The usual steps of a road run in one compiled call each.

The loop (sim/loop.py ``step_loop``) asks :class:`FusedPath` at the start of every step
whether the step is a usual one (:meth:`FusedPath.ready`); if so the whole step, sensing to the
members' new state and the recorded rows, is :func:`~.fused_step.fused_step`, and around it
Python does only what libsumo needs called (the reads, the moves, SUMO's step, the speeds)
and the events of the step, through the very watchers the loop's step uses. A member that
changed lanes is tracked by the adapter first (the read the loop's step would make); a
formation of a flow that is due but finds no room waits while the others' step is compiled;
near a ramp's join the merge watch's caps come from the members' sense before the call. Any
other step (a member enters or leaves SUMO, reaches into the next lane or nears a lane's
end, SUMO reported a collision or teleport, a table's part ends inside the step, a formation
enters or nears the end of its route, a signal was out of range at the step before, the
run's last step) is the loop's own: both work on the same objects (the world, the
generator, the fleet state, the recorder), so a run may take either path at any step and its
files are the same (tests/test_fused_step.py).

Runs it serves: one formation from t = 0, or a group of plain road formations (formation
flows included), on a road with a plain road reference (no maneuvers, no transforms such as a
radio, no shift at ramps), members placed by moveToXY (not SUMO's CACC twin), libsumo without
sumo-gui, kernels compiled (with ``NUMBA_DISABLE_JIT`` the loop's path
runs). With resistances the step computes the members' drag ratios and the road's grade
under them itself, with the loop's kernels (sim/road_load.py RoadLoad). Any law and model variant: with one registered at run time the compiled step is a copy
of fused_step calling the fleet's own step and signal kernels (sumo/fused_step.py
``fused_kernel``; compiled once per law and process, not cached on disk).
"""
from __future__ import annotations


import numpy as np

from ..control.reference_road import RoadReference
from ..record.columns import COMFORT_COLUMNS, FILLED_BY_CALLER, SIGNAL_COLUMNS
from ..control.reference_records import ReferenceOut
from ..sim.fleet_records import StateRecord, state_record
from ..sim.fleet_state import FleetState
from ..sim.loop import check_finite
from ..sim.road_load import RoadLoad
from .events import PLACEMENT_TOLERANCE
from .fused_records import RoadRun, SensedRows, StepAt, StepOut, fused_run
from .fused_refs import GroupOfFormations, OneFormation
from .sense import NeighbourReads, SumoRows, sense_step
from ..sim.step_flags import EMERGENCY, NOT_FINITE, OUT_OF_RANGE, SLOW, SWITCH, switched_off  # noqa: F401 (SWITCH re-exported)
from .fused_step import fused_kernel


_NO_READS = NeighbourReads(np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0))
"""sense_step's neighbours when only the members are sensed."""
_NO_NB = (np.empty((0, 7)), np.empty(0), np.empty((3, 0), dtype=np.int32), np.empty(0, dtype=np.int64))
"""fused_step's neighbour arguments for a step with no vehicle near the formation."""


class _NbView:
    """What sumo/events.py TrafficWatch reads of the neighbours (ids, lanes, lane indices)."""

    __slots__ = ("ids", "lane_ids", "lane_index")

    def __init__(self, ids, lane_ids, lane_index):
        self.ids, self.lane_ids, self.lane_index = ids, lane_ids, lane_index


_NO_VIEW = _NbView([], [], np.empty(0, dtype=np.int64))


def fused_path(parts, rec, sc, group=None):
    """The run's :class:`FusedPath`, or None when the run is not one it serves (module
    docstring); called by the loop once the run's parts are complete (``group``: its
    sim/formation_group.py FormationGroup, None for one formation)."""
    from numba import config

    from .world import SumoWorld
    world, fleet, forms = parts.world, parts.fleet, parts.formations
    one = (len(forms) == 1 and type(forms[0].generator) is RoadReference and not forms[0].transforms
           and not forms[0].depart)
    if (config.DISABLE_JIT or switched_off()
            or type(world) is not SumoWorld or world.baseline or world.adapter.gui
            or world.adapter.backend != "libsumo" or not _load_served(parts.road_load)
            or not (one or group is not None) or sc.maneuvers
            or rec.incidents is None or not rec.incidents.pairs):
        return None
    refs = OneFormation(forms[0].generator, world) if one else GroupOfFormations(group, world)
    return FusedPath(parts, rec, sc, refs)


def _load_served(load) -> bool:
    """The compiled step computes the road load itself (sim/road_load.py RoadLoad) or there is
    none to compute."""
    return load is None or isinstance(load, RoadLoad)


def _load_inputs(load, n: int) -> tuple[np.ndarray, ...]:
    """RoadRun's road-load fields: the run's RoadLoad's, or none to compute."""
    if load is None:
        return np.zeros((3, n)), np.zeros(0), np.zeros(0), np.zeros(0)
    return load.kernel_inputs(n)


class FusedPath:
    """The compiled step of a run's usual steps (module docstring). Per step:
    :meth:`ready` (the reads and the checks), :meth:`step` (the compiled call and the
    step's events; before the loop hands the step on), :meth:`finish` (after it: the
    control periods' rows, the moves and SUMO's step). ``refs``: the formations' reference
    state (sumo/fused_refs.py)."""

    def __init__(self, parts, rec, sc, refs):
        self.world, self.fleet, self.rec, self.refs = parts.world, parts.fleet, rec, refs
        w, fl = parts.world, parts.fleet
        gen = parts.formations[0].generator  # every formation's: the same control period
        self.n = n = fl.cfg.n
        self.step_s = float(sc.run.step)
        self.n_steps = int(round(sc.run.duration / sc.run.step))
        self.ids = list(fl.cfg.ids)
        k = len(parts.formations)
        self.road = RoadRun(w.line.G, PLACEMENT_TOLERANCE, w.d_front, self.step_s, refs.bodies,
                            refs.peers, w.slot_index, fl.cols, *_load_inputs(parts.road_load, n))
        self.ref_out = ReferenceOut(
            np.empty((gen.n_ctrl, n, 8)), np.empty(n), np.empty(k), np.empty(k), np.empty(k),
            np.empty(n), np.empty(n, dtype=np.int64), np.empty(n), np.empty(n), np.empty((k, 8)))
        self.out = StepOut(np.full((n, len(SIGNAL_COLUMNS)), np.nan), np.empty((gen.n_ctrl, n, 3)),
                           np.empty(n), np.empty(n), np.empty((6, n)), np.empty((n, 2)),
                           np.empty((n, 2)), np.empty(n), np.empty(n, dtype=np.int64))
        self._fused = fused_kernel(*fl.kernels)  # fused_step, or its copy for a runtime law
        self.run = fused_run(fl.params(gen.dt_c), self.road, refs.plan, refs.planner, self.ref_out,
                             rec.buffers, rec.incidents.arrays, self.out)
        self._slot = w.slot_index
        self._lanes_key = None  # the settled lanes the packed rows below are of
        self._li = self._lane_index = None
        self._all = np.arange(n)
        self._all_in = np.ones(n, dtype=np.bool_).tobytes()
        self._rows = self._nb_rows = None
        self._idx, self._every, self._flags = self._all, True, 0
        self._merging, self._no_limit = False, np.full(k, np.inf)
        self._all_present = np.ones(n, dtype=np.bool_)  # every member read (lane_changes' present)
        self._all_present.flags.writeable = False
        if len(FILLED_BY_CALLER) != 8 or len(COMFORT_COLUMNS) != 6:
            raise ValueError("fused_step writes the road and SUMO columns of record/columns.py")

    # ------------------------------------------------------------------ which steps
    def ready(self, k: int, t: float, state, clock) -> bool:
        """Is step k (at t [s]) a usual one? Reads SUMO's members and neighbours for
        :meth:`step` (nothing is changed: the loop's step reads again otherwise); ``clock``:
        the loop's sim/timing.py PhaseClock."""
        w, rec = self.world, self.rec
        act = w.active
        every = act.tobytes() == self._all_in
        if (k >= self.n_steps or not w.inserted or len(w.pending) or w.released or w.adopting
                or rec.any_out or (k + 1) % rec.steps_per_chunk == 0
                or w.slot_index is not self._slot or not self.refs.usual(t)
                or ((w.in_sumo.tobytes() != self._all_in) if every else (act & ~w.in_sumo).any())):
            return False
        ev = w.ev
        if ev is not None and (ev.collisions or ev.teleports):
            return False
        self._merging = w.merges is not None and w.merges.watching(w.m_s + w.d_front, act)
        idx = self._all if every else np.flatnonzero(act)
        n_act, tr, cf = len(idx), rec.traj, rec.comfort
        if (tr.rows_buffered + n_act + self.refs.vc_rows > tr.chunk_rows
                or cf.rows_buffered + n_act * self.out.periods.shape[0] > cf.chunk_rows):
            return False
        ids = w.sumo_ids if every else [w.sumo_ids[i] for i in idx]
        rows = w.adapter.settled_members(ids)
        if rows is None:  # a member changed lanes: the adapter tracks it (the read the loop's
            w.adapter.read_members(ids)  # step would make first; it finds nothing left to do)
            rows = w.adapter.settled_members(ids)
            if rows is None:  # a member SUMO no longer has, or in two lanes, or near a lane's end
                return False
        nb = w.adapter.neighbour_table(w.all_bg, native=True)
        if nb is not None and rec.background.rows_buffered + len(nb[0]) > rec.background.chunk_rows:
            return False
        if self.refs.enters(t, state):  # last: a due formation's room check reads SUMO
            return False
        self._rows, self._nb_rows, self._idx, self._every = rows, nb, idx, every
        clock.lap("sumo_read")
        return True

    # ------------------------------------------------------------------ the step
    def step(self, k: int, t: float, state, clock):
        """The usual step k at t [s] (after :meth:`ready`): the compiled call, the step's
        events and rows; returns the members' state at t + step."""
        w, rec, n, idx = self.world, self.rec, self.n, self._idx
        members, li, lane_index = self._members()
        nb = self._nb_rows
        if nb is None:
            nb_ids, nb_in = None, _NO_NB
        else:
            nb_ids, types, lane_ids, table, nb_li = nb
            nb_in = (table, w.nb_guess(nb_ids), rec.background_codes(nb_ids, types, lane_ids), nb_li)
        a_limit = self._no_limit
        if self._merging:  # ramp traffic near: the caps from the members' sense, in SumoWorld.sense's order
            a_limit = self._merge_caps(t, state, members, li)
        s, v = self.refs.before()
        tr, cf, refs = rec.traj, rec.comfort, self.refs
        sensed = SensedRows(members, li, lane_index, w.m_s, w.packed_lanes.table,
                            w.packed_lanes.points, *nb_in, w.active)
        at = StepAt(t, s, v, tr.rows_buffered, cf.rows_buffered, rec.background.rows_buffered,
                    refs.running, refs.parked, a_limit)
        x, ts, sp, ul, s_all, d_all, n_off, worst, flags = self._fused(
            self.run, state_record(state), StateRecord(*refs.held(state)), sensed, at)
        refs.after()
        self._flags = flags
        w.m_s = s_all[:n]
        if rec.incidents.lane_watch is not None:
            rec.incidents.lanes(t, d_all[:n], w.active)
        if nb_ids is not None:
            w.nb_guess.keep(nb_ids, s_all[n:])
        self._events(t, n_off, flags, worst, nb)
        tr.commit(len(idx) + refs.vc_rows)
        cf.commit(len(idx))
        clock.lap("fused_step")
        return FleetState(x, ts, sp, ul)

    def _merge_caps(self, t, state, members, li):
        """The formations' caps for ramp traffic (sumo/merge_watch.py MergeWatch.limits, its
        events and observations) from the members' sense: the members' part of
        :func:`~.sense.sense_step` as the compiled step computes it (each point is projected
        on its own), before it; the placement and lane-change events first, as SumoWorld.sense
        has them."""
        w, fl = self.world, self.fleet
        pos, vel, hd = fl.kinematics(state)
        s, d, v, gap, n_off = sense_step(
            w.line.G, pos, vel, w.m_s, hd, w.d_front,
            SumoRows(members[:, 0:2].copy(), members[:, 2].copy(), members[:, 4].copy(),
                     members[:, 3].copy(), li),
            w.packed_lanes.table, w.packed_lanes.points, PLACEMENT_TOLERANCE, _NO_READS)[:5]
        self._member_events(t, gap, n_off)
        w.merge_caps = w.merges.limits(t, s, d, v, w.active & w.in_sumo)
        return w.merge_caps

    def _member_events(self, t, gap, n_off) -> None:
        """The members' placement and lane-change events of the step (SumoWorld.sense's)."""
        w = self.world
        if n_off or w.members.off:
            w.members.placement(t, gap, n_off)
        _, lanes, lane_idx = self._rows
        present = self._all_present if self._every else np.ones(len(self._idx), dtype=np.bool_)
        w.members.lane_changes(t, self._idx, present, lanes, lane_idx)

    def _members(self):
        """The members' SUMO rows for the compiled step (NaN rows, lane row -1 and lane index
        NaN for those out of the run, as SumoWorld._member_rows gives them), their packed lane
        rows and their lane indices: kept while the members and their lanes stay the same."""
        table, lanes, lane_idx = self._rows
        idx = self._idx
        key = (lanes, idx.tobytes())
        if key != self._lanes_key:  # a member changed lanes or left the run
            self._lanes_key = key
            self.world.lanes_read = (idx, lanes)  # SumoWorld.locate's lanes
            self._li = np.full(self.n, -1, dtype=np.int64)
            self._li[idx] = self.world.packed_lanes.indices(lanes)
            self._lane_index = np.full(self.n, np.nan)
            self._lane_index[idx] = np.array(lane_idx, dtype=np.int64)
        if self._every:
            return table, self._li, self._lane_index
        full = np.full((self.n, 5), np.nan)
        full[idx] = table
        return full, self._li, self._lane_index

    def _events(self, t, n_off, flags, worst, nb) -> None:
        """The step's events in the loop's order: placement and lane changes (sense), emergency braking and
        the neighbours' lane changes and cut-ins (observe, then the background rows), signals
        out of range and the members' incidents (record)."""
        w, rec, out = self.world, self.rec, self.out
        if not self._merging:  # else before the compiled call (_merge_caps)
            self._member_events(t, self.out.m_gap, n_off)
        if flags & EMERGENCY or w.emergency.any_on:
            w.emergency(t, self.refs.emergency_info(self.ref_out.a_request, self.ref_out.a_cap_req))
        if nb is None:
            w.traffic(t, _NO_VIEW, out.lead_obs, self.ref_out.gap, out.v_m, w.active)
        else:
            w.traffic(t, _NbView(nb[0], nb[2], nb[4]), out.lead_obs, self.ref_out.gap, out.v_m, w.active)
            rec.background.commit(len(nb[0]))
        if flags & OUT_OF_RANGE or not self._every:  # Recorder.add_signal_rows' check
            rec.flag_range(t, out.sig, w.active)
        inc = rec.incidents
        if worst < 0.0 or flags & SLOW or inc.busy:
            inc.after_clearances(t, out.sig, w.active, worst)

    # ------------------------------------------------------------------ after the step
    def finish(self, k: int, t_next: float, state, clock) -> None:
        """After the loop handed step k on: its control periods' comfort rows, the
        generator's virtual car at the step's end, the moves and SUMO's step (``clock``: the
        loop's sim/timing.py PhaseClock)."""
        w, ad, idx = self.world, self.world.adapter, self._idx
        clock.lap("record")  # the loop's caller: the step's end, part files, progress (runner.py)
        if self.out.periods.shape[0] > 1:
            self.rec.comfort.commit((self.out.periods.shape[0] - 1) * len(idx))
        self.refs.settle(self.ref_out.s_next, self.ref_out.v_next)
        if self._flags & NOT_FINITE:
            check_finite(state, self.ids, t_next)
        place = self.out.place
        w.v_after, w.a_mean = place[3].copy(), place[4].copy()
        if w.true_v is not None:
            w.true_v[int(round(t_next / self.step_s))] = np.where(w.active, w.v_after, np.nan)
        w.placed(state, self.out.pos, self.out.vel, self.out.heading)  # the next sense's
        if self._every:
            ids, at = w.sumo_ids, place
        else:
            ids, at = [w.sumo_ids[i] for i in idx], place[:, idx]
        refused = ad.move_rows(ids, at[0], at[1], at[2], self.out.pos if self._every else self.out.pos[idx], at[5])
        if refused or w.refusals.counting:
            w.refusals(t_next, idx, refused, w.active, ad)
        clock.lap("sumo_place")
        w.ev = ad.step()
        if w.step_hook is not None:
            w.step_hook(k, t_next, ad)
        ad.tell_speeds(ids, at[5], at[4])
        if refused and not w.all_bg and w.active.any():  # a member dropped: SumoWorld.step's
            w.subscribe_contexts()
        if w.all_bg:
            ad.subscribe_departed()
        clock.lap("sumo_step")
