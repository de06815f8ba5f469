"""The usual steps of a road run in one compiled call each (issue 33, item 1).

The loop (sim/loop.py ``step_loop``) asks :class:`FusedPath` at the start of every step
whether the step is a usual one (:meth:`FusedPath.ready`); if so the whole step, sensing to the
members' new state and the recorded rows, is :func:`~.fused_step.fused_step`, and around it
Python does only what libsumo needs called (the reads, the moves, SUMO's step, the speeds)
and the events of the step, through the very watchers the loop's step uses. Any other step
(a member enters or leaves, changes lanes or overlaps the next lane, SUMO reported a
collision or teleport, a table's part ends inside the step, the formation nears the end of
its route, a signal was out of range at the step before, the run's last step) is the loop's
own: both work on the same objects (the world, the generator, the fleet state, the
recorder), so a run may take either path at any step and its files are the same
(tests/test_fused_step.py).

Runs it serves: one formation from t = 0 on a road with a plain road reference (no
maneuvers, no transforms such as a radio), members placed by moveToXY (not SUMO's CACC
twin), libsumo without sumo-gui, no driving resistances, kernels compiled (with
``NUMBA_DISABLE_JIT`` the loop's path runs).
"""
from __future__ import annotations

import os

import numpy as np

from ..control.reference_road import RoadReference
from ..record.columns import COMFORT_COLUMNS, FILLED_BY_CALLER, SIGNAL_COLUMNS
from ..sim.fleet import step_members
from ..sim.incidents import STRANDED_SPEED, STRANDED_V_REF, _H, _V, _VREF, _X, _Y
from ..sim.loop import check_finite
from .events import PLACEMENT_TOLERANCE
from .fused_step import EMERGENCY, NOT_FINITE, OUT_OF_RANGE, SLOW, fused_step
from .types import KEEP_ROUTE, MATCH_THRESHOLD

SWITCH = "FORMATION_TRACI_FUSED"
"""Environment variable: ``off`` runs every step through the loop's own path (a diagnostic:
the files are the same either way, tests/test_fused_step.py)."""

_NO_NB = (np.empty((0, 2)), np.empty(0), np.empty(0), np.empty(0), np.empty(0), np.empty(0),
          np.empty(0), np.empty((3, 0), dtype=np.int32), np.empty(0, dtype=np.int64))
"""The neighbours' arrays of a step with no vehicle near the formation."""


class _NbView:
    """What sumo/events.py TrafficWatch reads of the neighbours (ids, lanes, lane indices)."""

    __slots__ = ("ids", "lane_ids", "lane_index")

    def __init__(self, ids, lane_ids, lane_index):
        self.ids, self.lane_ids, self.lane_index = ids, lane_ids, lane_index


_NO_VIEW = _NbView([], [], np.empty(0, dtype=np.int64))


def fused_path(parts, rec, sc):
    """The run's :class:`FusedPath`, or None when the run is not one it serves (module
    docstring); called by the loop once the run's parts are complete."""
    from numba import config

    from .world import SumoWorld
    world, fleet, forms = parts.world, parts.fleet, parts.formations
    if (config.DISABLE_JIT or os.environ.get(SWITCH, "").lower() in ("0", "off", "no") or type(world) is not SumoWorld or world.baseline or world.adapter.gui
            or world.adapter.backend != "libsumo" or parts.road_load is not None
            or len(forms) != 1 or type(forms[0].generator) is not RoadReference
            or forms[0].transforms or forms[0].depart or sc.maneuvers
            or fleet._step is not step_members or rec.incidents is None or not rec.incidents.pairs):
        return None
    return FusedPath(parts, rec, sc)


class FusedPath:
    """The compiled step of a run's usual steps (module docstring). Per step:
    :meth:`ready` (the reads and the checks), :meth:`step` (the compiled call and the
    step's events; before the loop hands the step on), :meth:`finish` (after it: the
    control periods' rows, the moves and SUMO's step)."""

    def __init__(self, parts, rec, sc):
        self.world, self.fleet, self.rec = parts.world, parts.fleet, rec
        self.gen = parts.formations[0].generator
        fl, gen, n = self.fleet, self.gen, parts.fleet.cfg.n
        self.n, self.step_s = n, sc.run.step
        self.reach = gen.reach  # fixed for a run: the formation's front plus the end margin [m]
        self.n_steps = int(round(sc.run.duration / sc.run.step))
        self.fleet_args = (fl.kind, fl.P, fl.law, fl.L, fl.gains, fl.pred, fl.n_sub(gen.dt_c),
                           gen.dt_c, float(sc.run.step))
        pl = gen.longitudinal
        self.ref_args = (gen.prof, np.array([0, len(gen.prof)], dtype=np.int64))
        self.ref_members = (gen.along, gen.slot_d, gen.is_road, gen.half_w,
                            np.array([0, n], dtype=np.int64), gen.lim[None, :], pl.pp[None, :])
        self.planner = pl
        self.ramps = np.array([gen.ramp])
        self.vc = np.empty((gen.n_ctrl, n, 8))
        self.outs = tuple(np.empty(n) for _ in range(2))  # a_cap_from, gap
        self.lead_idx = np.empty(n, dtype=np.int64)
        self.caps = (np.empty(n), np.empty(n))  # a_cap_req, a_cap
        self.per_f = tuple(np.empty(1) for _ in range(3))  # a_request, s_next, v_next
        self.truth = np.empty((1, 8))
        self.sig = np.full((n, len(SIGNAL_COLUMNS)), np.nan)
        floats = rec._floats
        self.vc_cols = np.array([floats.index(c) for c in
                                 ("t", "x", "y", "heading", "v", "yaw_rate", "a_lon", "a_lat", "s", "d")],
                                dtype=np.int64)
        self.comfort_cols = rec._comfort_from
        inc = rec.incidents
        self.inc_args = (np.array([_X, _Y, _H, _V, _VREF], dtype=np.int64), inc.shift, inc.length,
                         inc.width, inc.clear, np.array([STRANDED_SPEED, STRANDED_V_REF]))
        self.periods = np.empty((gen.n_ctrl, n, 3))
        self.v_m, self.m_gap, self.place = np.empty(n), np.empty(n), np.empty((5, n))
        self.kin = (np.empty((n, 2)), np.empty((n, 2)), np.empty(n))
        self._lanes_key = None  # the settled lanes the packed rows below are of
        self._li = self._lane_index = None
        self._all = np.arange(n)
        self._nb = None  # this step's neighbours: (ids, lane ids, lane index) for the watches
        if len(FILLED_BY_CALLER) != 8 or len(COMFORT_COLUMNS) != 6:
            raise ValueError("fused_step writes the road and SUMO columns of record/columns.py")

    # ------------------------------------------------------------------ which steps
    def ready(self, k: int, t: float, state, clock) -> bool:
        """Is step k (at t [s]) a usual one? Reads SUMO's members and neighbours for
        :meth:`step` (nothing is changed: the loop's step reads again otherwise); ``clock``:
        the loop's sim/timing.py PhaseClock."""
        w, rec, gen, n = self.world, self.rec, self.gen, self.n
        if (k >= self.n_steps or not w.inserted or len(w.pending) or w.released or w.adopting
                or rec._any_out or gen.s + self.reach > gen.length
                or (k + 1) % rec.steps_per_chunk == 0 or not w.active.all() or not w.in_sumo.all()):
            return False
        ev = w.ev
        if ev is not None and (ev.collisions or ev.teleports):
            return False
        tr, cf = rec.traj, rec.comfort
        if (tr.rows_buffered + n + 1 > tr.chunk_rows
                or cf.rows_buffered + n * self.periods.shape[0] > cf.chunk_rows):
            return False
        rows = w.adapter.settled_members(w.sumo_ids)
        if rows is None or rows[2] != w.members._settled:
            return False
        nb = w.adapter.neighbour_rows(w.all_bg)
        if nb is not None and rec.background.rows_buffered + len(nb[0]) > rec.background.chunk_rows:
            return False
        self._rows, self._nb_rows = rows, nb
        clock.lap("sumo_read")
        return True

    # ------------------------------------------------------------------ the step
    def step(self, k: int, t: float, state, clock):
        """The usual step k at t [s] (after :meth:`ready`): the compiled call, the step's
        events and rows; returns the members' state at t + step."""
        w, rec, gen, n = self.world, self.rec, self.gen, self.n
        front, ang, lanes, lane_pos, lat, lane_idx = self._rows
        li, lane_index = self._packed(lanes, lane_idx)
        nb = self._nb_rows
        if nb is None:
            nb_ids = None
            nb_in = _NO_NB
        else:
            nb_ids, types, nb_front, nb_ang, nb_v, nb_a, length, width, lane_ids, nb_li = nb
            nb_in = (nb_front, nb_ang, length, width, w._nb_guess(nb_ids), nb_v, nb_a,
                     rec.background_codes(nb_ids, types, lane_ids), nb_li)
        pl, tr, cf, bg = self.planner, rec.traj, rec.comfort, rec.background
        s, v = np.array([gen.s]), np.array([gen.v])
        a_vc, em_vc = np.array([pl.a_vc]), np.array([pl.emergency_vc])
        has_prev = np.array([gen._has_prev])
        at, c_at = tr.rows_buffered, cf.rows_buffered
        x, ts, sp, ul, s_all, d_all, n_off, worst, flags = fused_step(
            *self.fleet_args, state.x, state.theta_star, state.speed_in, self.fleet._u_last(state),
            w.line.G, w.packed_lanes.table, w.packed_lanes.points, PLACEMENT_TOLERANCE, w.m_s, w.d_front, front, ang, lane_pos, lat, li, *nb_in[:7],
            *self.ref_args, t, s, v, *self.ref_members, a_vc, em_vc, pl.a_cap, gen._v_prev,
            has_prev, pl.emergency, self.ramps, gen.frame, gen.slots, self.vc, self.outs[0],
            self.per_f[0], self.per_f[1], self.per_f[2], self.outs[1], self.lead_idx,
            self.caps[0], self.caps[1], self.truth, self.sig, self.fleet.cols, rec._sig_limits,
            rec._float_block, rec._traj_ids, at, rec._cf_block, rec._cf_ids, c_at,
            self.comfort_cols, rec._extra_block, w.slot_index, lane_index, self.vc_cols,
            rec.vc_codes, rec._bg_floats, rec._bg_ints, bg.rows_buffered, nb_in[7], nb_in[8],
            *self.inc_args, self.periods, self.v_m, self.m_gap, self.place, *self.kin)
        gen._has_prev, pl.a_vc, pl.emergency_vc = True, float(a_vc[0]), bool(em_vc[0])
        self._next, self._flags = (float(self.per_f[1][0]), float(self.per_f[2][0])), flags
        w.m_s = s_all[:n]
        if nb_ids is not None:
            w._nb_guess.keep(nb_ids, s_all[n:])
        self._events(t, n_off, flags, worst, nb)
        tr.commit(n + 1)
        cf.commit(n)
        clock.lap("fused_step")
        return type(state)(x, ts, sp, ul)

    def _events(self, t, n_off, flags, worst, nb) -> None:
        """The step's events in the loop's order: placement (sense), emergency braking and
        the neighbours' lane changes and cut-ins (observe, then the background rows), signals
        out of range and the members' incidents (record)."""
        w, rec = self.world, self.rec
        if n_off or w.members._off:
            w.members.placement(t, self.m_gap, n_off)
        if flags & EMERGENCY or w.emergency._any_on:
            w.emergency(t, {"emergency_members": self.planner.emergency.copy(),
                            "emergency": self.planner.emergency_vc, "a_request": self.per_f[0][0],
                            "a_cap_request": self.caps[0]})
        view = _NO_VIEW if nb is None else _NbView(nb[0], nb[8], nb[9])
        w.traffic(t, view, self.lead_idx, self.outs[1], self.v_m, w.active)
        if nb is not None:
            rec.background.commit(len(nb[0]))
        if flags & OUT_OF_RANGE:
            rec.flag_range(t, self.sig, w.active)
        inc = rec.incidents
        if worst < 0.0 or flags & SLOW or inc.contact.any() or inc.is_stranded.any() or inc._standing:
            inc.after_clearances(t, self.sig, w.active, worst)

    def _packed(self, lanes: list[str], lane_idx):
        """The packed lane rows (sumo/sense.py PackedLanes) and the lane indices [-] of the
        members' settled lanes (the same until a member changes lanes)."""
        if lanes != self._lanes_key:
            self._lanes_key = lanes
            self._li = self.world.packed_lanes.indices(lanes)
            self._lane_index = np.array(lane_idx, dtype=np.int64).astype(float)
        return self._li, self._lane_index

    # ------------------------------------------------------------------ after the step
    def finish(self, k: int, t_next: float, state, clock) -> None:
        """After the loop handed step k on: its control periods' comfort rows, the
        generator's virtual car at the step's end, the moves and SUMO's step (``clock``: the
        loop's sim/timing.py PhaseClock)."""
        w, rec, ad, n = self.world, self.rec, self.world.adapter, self.n
        clock.lap("record")  # the loop's caller: the step's end, part files, progress (runner.py)
        if self.periods.shape[0] > 1:
            rec.comfort.commit((self.periods.shape[0] - 1) * n)
        self.gen.s, self.gen.v = self._next
        if self._flags & NOT_FINITE:
            check_finite(state, list(self.fleet.cfg.ids), t_next)
        place = self.place
        w.v_after, w.a_mean = place[3].copy(), place[4].copy()
        if w.true_v is not None:
            w.true_v[int(round(t_next / self.step_s))] = w.v_after.copy()
        w._kin = (state, *(a.copy() for a in self.kin))
        move, refused = ad._move_xy, {}
        for i, (vid, a, b, c) in enumerate(zip(w.sumo_ids, place[0].tolist(), place[1].tolist(),
                                               place[2].tolist())):
            try:
                move(vid, "", -1, a, b, c, KEEP_ROUTE, MATCH_THRESHOLD)
            except ad.api.TraCIException as exc:  # sumo/adapter.py place's message
                x, y = self.kin[0][i]
                refused[vid] = f"moveToXY refused for {vid} at ({x:.2f}, {y:.2f}): {exc}"
        w.refusals(t_next, self._all, refused, w.active, ad)
        clock.lap("sumo_place")
        w.ev = ad.step()
        if w.step_hook is not None:
            w.step_hook(k, t_next, ad)
        ad.set_true_speeds(w.sumo_ids, w.v_after, w.a_mean)
        if w.all_bg:
            ad.subscribe_departed()
        clock.lap("sumo_step")
