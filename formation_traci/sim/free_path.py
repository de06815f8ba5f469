"""The usual steps of a free-space run in one compiled call each.

The loop (sim/loop.py ``step_loop``) asks :class:`FreePath` at the start of every step whether
the step is a usual one (:meth:`FreePath.ready`); if so the whole step, the formations'
references to the members' new state and the recorded rows, is
:func:`~.free_step.free_step`, and around it Python does only the virtual cars' rows, the
step's events (signals out of range, the members' incidents) and the commits, through the
recorder's and the incidents' own code. Any other step (the run's last, a table's part ends
inside the step, a signal was out of range at the step before, a member out of the run) is
the loop's own: both work on the same objects (the generators, the fleet state, the
recorder), so a run may take either path at any step and its files are the same
(tests/test_free_fused.py).

Runs it serves: free space (sim/world.py FreeSpace) with one or several formations, each with
a control/reference_free.py FreeReference from t = 0, no transforms (no radio), no maneuvers,
kernels compiled (with ``NUMBA_DISABLE_JIT`` the loop's path runs),
and ``FORMATION_TRACI_FUSED`` not ``off``. Any law and model variant: with one registered at
run time the compiled step is a copy of free_step calling the fleet's own step and signal
kernels (sim/free_step.py ``free_kernel``; compiled once per law and process, not cached on
disk). With resistances and the drag interaction, the members' drag ratios of the step
(sim/road_load.py FreeSpaceLoad, the loop's own) are set before the compiled call.
"""
from __future__ import annotations


import numpy as np

from ..control.reference import FRAME_VEHICLE, NO_LINE
from ..control.reference_free import FreeReference
from ..models.params import N_PARAMS
from ..record.columns import SIGNAL_COLUMNS
from .fleet_records import FleetParams, StateRecord, as_f64, state_record
from .fleet_state import FleetState
from .free_step import FreeAt, FreeOut, FreePlan, free_kernel, free_run, free_step
from .incidents import IncidentArrays
from .road_load import FreeSpaceLoad
from .step_flags import NOT_FINITE, OUT_OF_RANGE, SLOW, SWITCH, switched_off  # noqa: F401 (SWITCH re-exported)
from .table_records import TableBuffers
from .world import FreeSpace

def free_path(parts, rec, sc, check_finite):
    """The run's :class:`FreePath`, or None when the run is not one it serves (module
    docstring); called by the loop once the run's parts are complete (``check_finite``:
    sim/loop.py's, raised at a step whose new state is not finite)."""
    from numba import config

    world, forms = parts.world, parts.formations
    if (config.DISABLE_JIT or switched_off() or type(world) is not FreeSpace
            or not world.records_members or sc.maneuvers
            or not (parts.road_load is None or isinstance(parts.road_load, FreeSpaceLoad))
            or rec.incidents is None or rec.incidents.lane_watch is not None):
        return None
    at = 0
    for f in forms:
        g = f.generator
        if (type(g) is not FreeReference or f.transforms or f.depart or f.status != "running"
                or f.members.start != at or f.members.stop <= at or f.members.step not in (None, 1)
                or g.n_ctrl != forms[0].generator.n_ctrl or g.dt_c != forms[0].generator.dt_c):
            return None
        at = f.members.stop
    if at != parts.fleet.cfg.n:
        return None
    return FreePath(parts, rec, sc, check_finite)


class FreePath:
    """The compiled step of a free-space run's usual steps (module docstring). Per step:
    :meth:`ready` (the checks), :meth:`step` (the compiled call, the virtual cars' rows and
    the step's events; before the loop hands the step on), :meth:`finish` (after it: the
    control periods' rows committed, the virtual cars moved on)."""

    def __init__(self, parts, rec, sc, check_finite):
        self.world, self.fleet, self.rec = parts.world, parts.fleet, rec
        self.check_finite = check_finite
        self.gens = [f.generator for f in parts.formations]
        fl, g0 = parts.fleet, self.gens[0]
        self.n = n = fl.cfg.n
        self.n_ctrl = g0.n_ctrl
        self.step_s = float(sc.run.step)
        self.n_steps = int(round(sc.run.duration / sc.run.step))
        self.ids = list(fl.cfg.ids)
        k = len(self.gens)
        profs = [g.prof for g in self.gens]
        prof_at = np.cumsum([0] + [len(p) for p in profs]).astype(np.int64)
        rows_at = np.array([0] + [f.members.stop for f in parts.formations], dtype=np.int64)
        slots = g0.slots if k == 1 else np.concatenate([g.slots for g in self.gens], axis=1)
        self.plan = FreePlan(NO_LINE, np.full(n, FRAME_VEHICLE, dtype=np.int64), as_f64(slots),
                             np.full(n, np.inf), as_f64(np.concatenate(profs)), prof_at, rows_at,
                             np.array([g.n_sub for g in self.gens], dtype=np.int64), fl.cols,
                             np.ones(n, dtype=np.bool_), bool(rec.incidents.pairs))
        self.out = FreeOut(np.full((n, len(SIGNAL_COLUMNS)), np.nan), np.empty((self.n_ctrl, n, 3)),
                           np.empty((self.n_ctrl, n, 8)), np.empty((k, 3)), np.empty((k, 3)),
                           np.empty((k, 8)))
        self.load = parts.road_load  # FreeSpaceLoad or None
        self._free = free_kernel(*fl.kernels)  # free_step, or its copy for a runtime law
        self.run = free_run(fl.params(g0.dt_c), self.plan, rec.buffers, rec.incidents.arrays, self.out)
        self._all_in = np.ones(n, dtype=np.bool_).tobytes()
        self._flags = 0

    def ready(self, k: int, t: float, state, clock) -> bool:
        """Is step k (at t [s]) a usual one? (``clock``: the loop's sim/timing.py PhaseClock.)"""
        rec = self.rec
        if (k >= self.n_steps or rec.any_out or (k + 1) % rec.steps_per_chunk == 0
                or self.world.sensed.active.tobytes() != self._all_in):
            return False
        tr, cf, n = rec.traj, rec.comfort, self.n
        return (tr.rows_buffered + n + len(self.gens) <= tr.chunk_rows
                and cf.rows_buffered + n * self.n_ctrl <= cf.chunk_rows)

    def step(self, k: int, t: float, state, clock):
        """The usual step k at t [s] (after :meth:`ready`): the compiled call, the virtual
        cars' rows and the step's events; returns the members' state at t + step."""
        rec, n, out = self.rec, self.n, self.out
        pose = out.pose
        for f, g in enumerate(self.gens):
            pose[f] = g.pose
        if self.load is not None:  # the drag ratios of the step, as the loop sets them
            self.fleet.set_road_load(self.load.ratios(state.x[:, :2], [g.pose[2] for g in self.gens]))
        tr, cf = rec.traj, rec.comfort
        x, ts, sp, ul, worst, flags = self._free(
            self.run, state_record(state), FreeAt(float(t), tr.rows_buffered, cf.rows_buffered))
        self._flags = flags
        tr.commit(n)
        rec.add_vcs(t, out.truth)  # the virtual cars' rows after the members' (Recorder.add_step)
        cf.commit(n)
        active = self.world.sensed.active
        if flags & OUT_OF_RANGE:  # Recorder.add_signal_rows' events
            rec.flag_range(t, out.sig, active)
        inc = rec.incidents
        if worst < 0.0 or flags & SLOW or inc.busy:
            inc.after_clearances(t, out.sig, active, worst)
        clock.lap("fused_step")
        return FleetState(x, ts, sp, ul)

    def finish(self, k: int, t_next: float, state, clock) -> None:
        """After the loop handed step k on: its control periods' comfort rows, the virtual
        cars at the step's end, the finite check (sim/loop.py check_finite)."""
        clock.lap("record")  # the loop's caller: the step's end, part files, progress (runner.py)
        if self.n_ctrl > 1:
            self.rec.comfort.commit((self.n_ctrl - 1) * self.n)
        nxt = self.out.pose_next
        for f, g in enumerate(self.gens):  # FreeReference.commit
            g.pose = tuple(nxt[f].tolist())
        if self._flags & NOT_FINITE:
            self.check_finite(state, self.ids, t_next)
        clock.lap("control_model")


def warm_kernels() -> None:
    """Compile (or load) :func:`~.free_step.free_step` for the argument types a free-space run
    passes, on zero members of one formation (sim/warm.py)."""
    z, zi = np.zeros(0), np.zeros(0, dtype=np.int64)
    fleet = FleetParams(0, np.zeros((0, N_PARAMS)), zi, np.zeros((0, 1)), np.zeros((0, 6)), zi, 1, 0.01)
    plan = FreePlan(NO_LINE, zi, np.zeros((0, 0, 6)), z, np.zeros(8), np.array([0, 8]),
                    np.array([0, 0]), np.ones(1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                    np.zeros(0, dtype=np.bool_), True)
    ids = np.zeros(0, dtype=np.int32)
    tables = TableBuffers(z, np.zeros((0, 0)), ids, np.zeros((0, 0)), ids, zi, np.zeros((0, 0)),
                          zi, ids, np.empty((0, 0)), np.empty((0, 0), dtype=np.int32))
    inc = IncidentArrays(zi, z, z, z, np.zeros((0, 0)), np.zeros(2), np.zeros(0, dtype=np.bool_))
    out = FreeOut(np.zeros((0, len(SIGNAL_COLUMNS))), np.zeros((0, 0, 3)), np.zeros((0, 0, 8)),
                  np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 8)))
    free_step(free_run(fleet, plan, tables, inc, out),
              StateRecord(np.zeros((0, 1)), z, z, z), FreeAt(0.0, 0, 0))
