"""The usual step of a free-space run as one compiled call.

:func:`free_step` runs, for every member of every formation, what the loop (sim/loop.py
``step_loop``) runs in a free-space step where nothing out of the ordinary happens, in the
loop's order and through the very kernels the loop calls one by one:

    reference  control/reference_free.py free_vc_rows per formation (its virtual car's rows
               at every control period, its pose at the step's end)
    record     sim/fleet.py member_signals (the members' signals), sim/fleet_rows.py
               signal_table_rows (their trajectory and comfort rows), the trajectory's road
               columns (none in free space: NaN, ``leader_age_s`` 0), sim/incidents.py
               member_clearances
    control    sim/fleet.py step_members (every control period), sim/fleet_rows.py
               period_table_rows (the comfort rows of periods 1 .. n_ctrl - 1)

Everything it writes goes into arrays the caller owns (the tables' buffers at the rows it
names, the records' output arrays); the virtual cars' rows, the events and the commits of the
tables stay in Python (sim/free_path.py), which also decides which steps are usual. The
results are those of the loop's step, bit for bit (tests/test_free_fused.py).

The records (named tuples of arrays, one structref of them; n members, k formations, n_ctrl control periods):

run     :class:`FreeRun` (a numba structref, made once per run by :func:`free_run`):
        ``fleet`` (sim/fleet_records.py FleetParams), ``plan`` (:class:`FreePlan`), ``tables``
        (sim/table_records.py TableBuffers, sim/recorder.py Recorder.buffers), ``inc``
        (sim/incidents.py IncidentArrays), ``out`` (:class:`FreeOut`);
state   sim/fleet_records.py StateRecord: the members' state at t;
at      :class:`FreeAt`: t [s] and the step's first rows of the tables' buffers.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import types
from numba.experimental import structref

from ..control.reference_free import free_vc_rows
from ..control.reference_records import StepReference
from ..core.kernels import kernel
from .fleet import member_signals, step_members
from .step_copies import with_fleet_kernels
from .fleet_rows import period_table_rows, signal_table_rows
from .incidents import member_clearances, slow_members
from .record_rows import beyond_limits
from .step_flags import NOT_FINITE, OUT_OF_RANGE, SLOW
from .table_records import SignalRows



class FreePlan(NamedTuple):
    """The formations' fixed reference data (control/reference_free.py FreeReference of each,
    members in formation order) and what the step's records need of the fleet."""

    G: np.ndarray  # the reference line (control/reference.py NO_LINE: none)
    frame: np.ndarray  # (n,) slot frame codes (FRAME_VEHICLE)
    slots: np.ndarray  # (n_ctrl, n, 6) the members' slots (control/reference.py SLOT_FIELDS)
    cap: np.ndarray  # (n,) speed and acceleration caps (inf: none)
    prof: np.ndarray  # every formation's packed speed and yaw-rate profiles, one after the other
    prof_at: np.ndarray  # (k + 1,) where formation f's profiles start in ``prof`` (and end)
    rows_at: np.ndarray  # (k + 1,) formation f's members are rows rows_at[f] .. rows_at[f + 1]
    n_sub: np.ndarray  # (k,) RK4 sub-steps of each virtual car per control period [-]
    cols: np.ndarray  # (N_SIGNALS,) signal column of each kernel signal (sim/fleet.py)
    active: np.ndarray  # (n,) the members in the run (every one: the usual step)
    pairs: bool  # the members' clearances are watched (sim/incidents.py Incidents.pairs)


class FreeOut(NamedTuple):
    """The step's outputs beyond its return values (the same arrays every step)."""

    sig: np.ndarray  # (n, signal columns) the members' signals
    periods: np.ndarray  # (n_ctrl, n, 3) speed [m/s], a_lon, a_lat [m/s^2] per control period
    vc: np.ndarray  # (n_ctrl, n, 8) each member's virtual car per control period
    pose: np.ndarray  # (k, 3) the virtual cars' x, y [m], theta [rad] at t (read)
    pose_next: np.ndarray  # (k, 3) the same at the step's end (written)
    truth: np.ndarray  # (k, 8) the virtual cars' recorded rows (control/reference.py Reference.truth)


@structref.register
class FreeRunType(types.StructRef):
    """numba's type of a :class:`FreeRun`."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class FreeRun(structref.StructRefProxy):
    """The records that stay the same over a run, in one object the compiled code holds by
    reference (passed to a compiled call as one pointer: a named tuple is unpacked field by
    field at every call). Fields: ``fleet`` (sim/fleet_records.py FleetParams), ``plan``
    (:class:`FreePlan`), ``tables`` (sim/table_records.py TableBuffers), ``inc``
    (sim/incidents.py IncidentArrays), ``out`` (:class:`FreeOut`). Made by :func:`free_run`."""


structref.define_proxy(FreeRun, FreeRunType, ["fleet", "plan", "tables", "inc", "out"])


@kernel
def free_run(fleet, plan, tables, inc, out):
    """The :class:`FreeRun` of these records (compiled and cached: no compilation at a run's
    start)."""
    return FreeRun(fleet, plan, tables, inc, out)


class FreeAt(NamedTuple):
    """The step's time and where its rows go."""

    t: float  # [s]
    at: int  # the step's first row of the trajectory table's buffer
    c_at: int  # of the comfort table's


def free_kernel(step, signals):
    """:func:`free_step` for a fleet whose step and signal kernels (sim/fleet.py
    Fleet.kernels) are ``step`` and ``signals``: the cached kernel itself for the package's
    own :func:`~.fleet.step_members` and :func:`~.fleet.member_signals`, else a compiled copy
    calling those given (a law registered at run time, a model variant), made once per pair
    (compiled on first call, not cached on disk)."""
    return with_fleet_kernels(free_step, _record, (step, signals))


@kernel
def free_step(run, state, at):
    """One usual step of the free-space run at ``at.t`` [s] (module docstring: what it runs,
    the records). Returns (x, theta_star, speed_in, u_last) after the step, the smallest
    clearance between members [m] (+inf: none watched) and the flags OUT_OF_RANGE |
    NOT_FINITE | SLOW."""
    fleet, plan, out = run.fleet, run.plan, run.out
    t = at.t
    _references(plan, out, t, fleet.dt_c)
    targets = StepReference(plan.G, plan.frame, out.vc, plan.slots, plan.cap, plan.cap, plan.cap,
                            np.ones(plan.cap.shape[0], dtype=np.bool_))
    flags, worst = _record(fleet, plan, targets, run.tables, run.inc, out, state, at)
    tables = run.tables
    x1, ts1, sp1, ul1 = step_members(fleet, state, targets, out.periods, t, tables.comfort,
                                     tables.comfort_ids, -1)
    n = x1.shape[0]
    if out.periods.shape[0] > 1:
        period_table_rows(out.periods, t, fleet.dt_c, tables.comfort, tables.comfort_ids,
                          at.c_at + n, plan.active)
    for i in range(n):
        for q in range(x1.shape[1]):
            if not math.isfinite(x1[i, q]):
                flags |= NOT_FINITE
    return x1, ts1, sp1, ul1, worst, flags


@kernel
def _references(plan, out, t, dt_c):
    """Every formation's virtual car at the control periods of the step at t [s] into its
    members' rows of ``out.vc`` (free_vc_rows, as FreeReference.reference), its recorded row
    into ``out.truth`` and its pose at the step's end into ``out.pose_next``."""
    vc, pose, nxt, truth = out.vc, out.pose, out.pose_next, out.truth
    for f in range(plan.n_sub.shape[0]):
        a, b = plan.rows_at[f], plan.rows_at[f + 1]
        X, Y, th = free_vc_rows(plan.prof[plan.prof_at[f]:plan.prof_at[f + 1]], t, pose[f, 0],
                                pose[f, 1], pose[f, 2], dt_c, plan.n_sub[f], vc[:, a:b, :])
        nxt[f, 0] = X
        nxt[f, 1] = Y
        nxt[f, 2] = th
        if b > a:  # its members' copy of the period 0 virtual car
            for q in range(8):
                truth[f, q] = vc[0, a, q]
        else:  # no member: its pose (FreeReference.reference)
            truth[f, 0] = pose[f, 0]
            truth[f, 1] = pose[f, 1]
            truth[f, 2] = pose[f, 2]
            for q in range(3, 7):
                truth[f, q] = 0.0
            truth[f, 7] = np.nan


@kernel
def _record(fleet, plan, targets, tables, inc, out, state, at):
    """The step's recorded rows: member_signals on the step's reference ``targets``, the
    members' trajectory and comfort rows (signal_table_rows) and their road columns (NaN, the
    radio's leader_age_s 0: free space without a channel), the members' clearances. Returns
    (OUT_OF_RANGE | SLOW, the smallest clearance [m])."""
    t, sig = at.t, out.sig
    member_signals(fleet, state, targets, plan.cols, sig, t,
                   SignalRows(tables.limits, tables.traj, tables.traj_ids, -1, tables.comfort,
                              tables.comfort_ids, at.c_at, tables.comfort_cols))
    n = signal_table_rows(sig, t, tables.traj, tables.traj_ids, at.at, tables.comfort,
                          tables.comfort_ids, at.c_at, tables.comfort_cols, plan.active)
    extras, c = tables.extras, inc.cols
    for i in range(n):  # no road columns in free space; the radio's leader_age_s 0
        for q in range(extras.shape[0] - 1):
            extras[q, at.at + i] = np.nan
        extras[extras.shape[0] - 1, at.at + i] = 0.0
    flags = 0
    if beyond_limits(sig, tables.limits):
        flags |= OUT_OF_RANGE
    if slow_members(sig, c[3], c[4], inc.stranded, plan.active, inc.slow):
        flags |= SLOW
    worst = np.inf
    if plan.pairs:
        worst = member_clearances(sig, c[0], c[1], c[2], inc.shift, inc.length, inc.width,
                                  plan.active, inc.clear)
    return flags, worst
