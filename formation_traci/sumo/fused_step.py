"""The usual step of a road run as one compiled call.

:func:`fused_step` runs, for every member of every formation, what the loop (sim/loop.py
``step_loop``) runs in a step where nothing out of the ordinary happens, in the loop's order
and through the very kernels the loop calls one by one:

    sense      sim/fleet.py kinematics_rows, sumo/sense.py sense_step
    reference  control/reference_group.py group_reference_step (road_reference_step per
               formation: governor, planner, the virtual car's rows)
    observe    the neighbours' background rows
    record     sim/fleet.py member_signals (the members' trajectory and comfort rows), the
               road and SUMO columns, one virtual-car row per formation,
               sim/incidents.py member_clearances
    control    sim/fleet.py step_members (every control period, the comfort rows of periods
               1 .. n_ctrl - 1)
    actuate    the new state's poses in SUMO's frame (sumo/types.py cog_to_sumo_rows), the
               members' speeds and mean accelerations over the step

Everything a step writes goes into arrays the caller owns (the tables' buffers at the rows
it names, the planners' state in place); events, string columns and SUMO's calls stay in
Python (sumo/fused_path.py), which also decides which steps are usual. The results are those
of the loop's step, bit for bit (tests/test_fused_step.py).

The arguments of :func:`fused_step` are records (named tuples of arrays, the fields named
and their units given where each is defined): ``run`` (sumo/fused_records.py FusedRun, built
once per run: the same arrays every step) holds the first eight below, the last four are the
step's:

fleet     sim/fleet_records.py FleetParams (sim/fleet.py Fleet.params: the model, the laws,
          the gains, the sub-steps and the control period);
road      sumo/fused_records.py RoadRun: the reference line, the placement tolerance, the
          members' bodies (CoG to front bumper as the reference takes it, length, width and
          CoG to front bumper as SUMO has them [m]), with ``peers`` (several formations) each
          formation seeing the others' members as traffic (sumo/peers.py), the SUMO step;
plan      control/reference_records.py GroupPlan: the formations' profiles, slots, limits
          and planner settings (control/reference_group.py group_reference_step's; each
          formation's own time is t - ``depart`` [s]);
planner   control/reference_records.py PlannerState: the planners' state, updated in place;
ref       control/reference_records.py ReferenceOut: the references' outputs of the step
          (the virtual cars' rows, the caps, the gaps and leaders, ``truth``);
tables    sim/table_records.py TableBuffers (sim/recorder.py Recorder.buffers): the tables'
          buffers the step's rows go into, from the rows ``at`` names (a signal beyond
          ``limits`` is flagged and its row written all the same, as the recorder writes
          it; the trajectory's road and SUMO columns go into ``extras``, one virtual-car row
          per running formation after the members');
inc       sim/incidents.py IncidentArrays (Incidents.arrays): the bodies and the clearance
          matrix of member_clearances, the stranded thresholds;
out       sumo/fused_records.py StepOut: the members' signals, step_members' comfort rows
          per control period (written at c_at + n of the comfort table), the speeds and
          gaps as sensed (the sumo_gap column), SUMO's placement of the new state
          (``place``) and its CoG kinematics, the members' leaders among SUMO's vehicles
          (``lead_obs``: -1 none, or a member);
state     sim/fleet_records.py StateRecord: the members' state at t;
held      the same of the parked rows (sim/formation_group.py FormationGroup.settle);
sensed    sumo/fused_records.py SensedRows: SUMO's rows of the members (NaN rows, packed
          lane row -1 for those out of the run) and of the neighbours, the packed lanes,
          ``active`` the members in the run (rows are recorded for them only);
at        sumo/fused_records.py StepAt: t [s], the virtual cars' s and v, the first rows of
          the step in the tables' buffers, ``running`` the formations running (the others'
          virtual cars stand), ``parked`` their members' rows (held at ``held``).
"""
from __future__ import annotations

import math

import numpy as np

from ..control.reference_group import group_reference_step
from ..control.reference_records import MemberRows, NeighbourRows, StepReference
from ..core.kernels import kernel, maximum, rebind
from ..models.bicycle import S
from ..models.state import KINEMATIC
from ..sim.fleet import kinematics_rows, member_signals, step_members
from ..sim.fleet_rows import period_table_rows, signal_table_rows
from ..sim.incidents import member_clearances
from ..sim.table_records import SignalRows
from .sense import NeighbourReads, SumoRows, sense_step
from .types import cog_to_sumo_rows

OUT_OF_RANGE = 1
"""fused_step flag: a recorded signal is beyond the recorder's limits (a model_range event)."""
NOT_FINITE = 2
"""fused_step flag: the members' new state is not finite (sim/loop.py ModelRangeError)."""
SLOW = 4
"""fused_step flag: a member stands while its speed reference does not (sim/incidents.py)."""
EMERGENCY = 8
"""fused_step flag: the virtual car or a member is on emergency braking (sumo/events.py)."""

_COPIES: dict = {}


def fused_kernel(step, signals):
    """:func:`fused_step` for a fleet whose step and signal kernels (sim/fleet.py
    Fleet.kernels) are ``step`` and ``signals``: the cached kernel itself for the package's
    own :func:`~..sim.fleet.step_members` and :func:`~..sim.fleet.member_signals`, else a
    compiled copy calling those given (a law registered at run time: sim/fleet_laws.py
    law_kernels), made once per pair (compiled on first call, not cached on disk)."""
    if step is step_members and signals is member_signals:
        return fused_step
    key = (id(step), id(signals))
    got = _COPIES.get(key)
    if got is None or got[0] is not step or got[1] is not signals:
        record = rebind(_record, member_signals=signals)
        got = _COPIES[key] = (step, signals, rebind(fused_step, step_members=step, _record=record))
    return got[2]


@kernel
def fused_step(run, state, held, sensed, at):
    """One usual step of the road run at ``at.t`` [s]: the module docstring says what it
    runs and what each record is ("The arguments"). Returns (x, theta_star, speed_in, u_last)
    after the step, the members' and the neighbours' arc lengths and offsets (n + m,) [m],
    the count of members farther than ``road.tolerance`` from where SUMO has them, the
    smallest clearance between members [m] and the flags OUT_OF_RANGE | NOT_FINITE | SLOW |
    EMERGENCY."""
    fleet, road, plan, planner, ref = run.fleet, run.road, run.plan, run.planner, run.ref
    tables, inc, out = run.tables, run.inc, run.out
    t = at.t
    x, speed_in, nb, members = state.x, state.speed_in, sensed.nb, sensed.members
    n = x.shape[0]
    nb_length = nb[:, 5].copy()
    nb_width = nb[:, 6].copy()
    nb_v = nb[:, 3].copy()
    pos0, vel0, hd0 = kinematics_rows(x, speed_in, fleet.kind)  # sense (SumoWorld.sense)
    s_all, d_all, v_sense, g, n_off, nb_x, nb_y, nb_psi, rear, nb_half_w = sense_step(
        road.G, pos0, vel0, sensed.s_guess, hd0, road.d_front,
        SumoRows(members[:, 0:2].copy(), members[:, 2].copy(), members[:, 4].copy(),
                 members[:, 3].copy(), sensed.li), sensed.lane_table, sensed.lane_points,
        road.tolerance, NeighbourReads(nb[:, 0:2].copy(), nb[:, 2].copy(), nb_length, nb_width,
                                       sensed.nb_guess))
    for i in range(n):
        out.v_m[i] = v_sense[i]
        out.m_gap[i] = g[i]
    flags = _reference(road, plan, planner, ref, at, s_all[:n], d_all[:n], v_sense,
                       sensed.active, (rear, d_all[n:], nb_half_w, nb_v), fleet.dt_c)
    m = nb.shape[0]
    for i in range(n):
        out.lead_obs[i] = ref.lead_idx[i] if ref.lead_idx[i] < m else -1
    _background_rows(tables, sensed, at.bg_at, t, nb_x, nb_y, nb_psi, s_all[n:], d_all[n:])
    targets = StepReference(road.G, plan.frame, ref.vc, plan.slots, np.full(n, np.inf),
                            ref.a_cap, ref.a_cap_from)
    rec_flags, n_act, worst = _record(fleet, road, targets, tables, inc, out, state, sensed, at,
                                      (s_all, d_all), ref.truth)
    flags |= rec_flags
    x1, ts1, sp1, ul1 = step_members(fleet, state, targets, out.periods, t, tables.comfort,
                                     tables.comfort_ids, -1)
    if out.periods.shape[0] > 1:
        period_table_rows(out.periods, t, fleet.dt_c, tables.comfort, tables.comfort_ids,
                          at.c_at + n_act, sensed.active)
    for i in range(n):  # the members of formations not running stay where they are
        if at.parked[i]:
            x1[i] = held.x[i]
            ts1[i] = held.theta_star[i]
            sp1[i] = held.speed_in[i]
            ul1[i] = held.u_last[i]
    flags |= _placed(fleet.kind, x, speed_in, x1, sp1, road, out)
    return x1, ts1, sp1, ul1, s_all, d_all, n_off, worst, flags


@kernel
def _record(fleet, road, targets, tables, inc, out, state, sensed, at, sd, truth):
    """The step's recorded rows (member_signals on the step's reference ``targets``, the road
    and SUMO columns, the virtual cars' rows from ``truth``) and the members' clearances;
    ``sd``: the members' and neighbours' arc lengths and offsets [m]. Returns (OUT_OF_RANGE |
    SLOW, the members' rows written, the smallest clearance [m])."""
    t = at.t
    member_signals(fleet, state, targets, road.cols, out.sig, t,
                   SignalRows(tables.limits, tables.traj, tables.traj_ids, -1, tables.comfort,
                              tables.comfort_ids, at.c_at, tables.comfort_cols))
    n_act = signal_table_rows(out.sig, t, tables.traj, tables.traj_ids, at.at, tables.comfort,
                              tables.comfort_ids, at.c_at, tables.comfort_cols, sensed.active)
    flags = _road_columns(out, tables, road, inc, truth, sensed, at, sd[0], sd[1])
    c = inc.cols
    worst = member_clearances(out.sig, c[0], c[1], c[2], inc.shift, inc.length, inc.width,
                              sensed.active, inc.clear)
    return flags, n_act, worst


@kernel
def _reference(road, plan, planner, ref, at, m_s, m_d, v_m, active, nbs, dt_c):
    """Every formation's reference (group_reference_step at each formation's own time
    ``at.t - plan.depart`` [s], the ``at.running`` ones moving, no released member among the
    neighbours ``nbs``: their rears, offsets, half widths [m] and speeds [m/s]; with
    ``road.peers`` SUMO's vehicles joined by every member in the run: sumo/peers.py
    Peers.table); returns EMERGENCY when a running virtual car or a member in the run is on
    emergency braking, else 0."""
    nb_rear, nb_d, nb_half_w, nb_v = nbs
    bodies, running = road.bodies, at.running
    k = at.s.shape[0]
    m = nb_rear.shape[0]
    n = 0
    if road.peers:
        for i in range(m_s.shape[0]):
            if active[i]:
                n += 1
    rear = np.empty(m + n)
    d = np.empty(m + n)
    half = np.empty(m + n)
    speed = np.empty(m + n)
    owner = np.full(m + n, -1, dtype=np.int64)
    for j in range(m):
        rear[j] = nb_rear[j]
        d[j] = nb_d[j]
        half[j] = nb_half_w[j]
        speed[j] = nb_v[j]
    q = m
    for i in range(m_s.shape[0] if road.peers else 0):  # Peers.update's rear (front bumper
        if not active[i]:  # less the length), Peers.table's rows of the members in the run
            continue
        rear[q] = m_s[i] + bodies[3, i] - bodies[1, i]
        d[q] = m_d[i]
        half[q] = bodies[2, i] / 2
        speed[q] = v_m[i]
        owner[q] = i
        q += 1
    group_reference_step(plan, planner, ref, at.t - plan.depart, at.s, at.v, running,
                         at.a_limit, MemberRows(m_s, m_d, v_m, active),
                         NeighbourRows(rear, d, half, speed, np.zeros(m + n, dtype=np.bool_),
                                       np.empty(0)), owner, dt_c)
    for f in range(k):
        if running[f] and planner.emergency_vc[f]:
            return EMERGENCY
    emergency = planner.emergency
    for i in range(emergency.shape[0]):
        if emergency[i]:
            return EMERGENCY
    return 0


@kernel
def _background_rows(tables, sensed, at, t, x, y, psi, s, d):
    """The neighbours' rows of the background table from row ``at`` (Recorder.add_background):
    their poses ``x``, ``y`` [m], ``psi`` [rad], arc lengths ``s`` and offsets ``d`` [m], the
    rest from ``sensed`` (its rows ``nb``, string codes ``bg_codes`` and lane indices)."""
    fl, ints, nb, codes = tables.bg_floats, tables.bg_ints, sensed.nb, sensed.bg_codes
    for j in range(x.shape[0]):
        r = at + j
        fl[0, r] = t
        fl[1, r] = x[j]
        fl[2, r] = y[j]
        fl[3, r] = psi[j]
        fl[4, r] = nb[j, 3]
        fl[5, r] = nb[j, 4]
        fl[6, r] = nb[j, 5]
        fl[7, r] = nb[j, 6]
        fl[8, r] = s[j]
        fl[9, r] = d[j]
        for q in range(3):
            ints[q, r] = codes[q, j]
        ints[3, r] = sensed.nb_lane_index[j]


@kernel
def _road_columns(out, tables, road, inc, truth, sensed, at, s_all, d_all):
    """After the members' rows (those in the run, ``sensed.active``): their road and SUMO
    columns at rows ``at.at`` .. of the trajectory table (Recorder.add_step's ``extra``), each
    running formation's virtual-car row after them; returns OUT_OF_RANGE (a signal beyond the
    recorder's ``tables.limits``: member_signals' test) | SLOW (a member stands while its
    speed reference does not: sim/incidents.py)."""
    flags = 0
    sig, limits, extras, cols, stranded = out.sig, tables.limits, tables.extras, inc.cols, inc.stranded
    n = sig.shape[0]
    r = at.at
    for i in range(n):
        for q in range(sig.shape[1]):
            if abs(sig[i, q]) > limits[q]:
                flags |= OUT_OF_RANGE
        if sig[i, cols[3]] < stranded[0] and sig[i, cols[4]] > stranded[1]:
            flags |= SLOW
        if not sensed.active[i]:
            continue
        extras[0, r] = s_all[i]
        extras[1, r] = d_all[i]
        extras[2, r] = sensed.lane_index[i]
        extras[3, r] = out.m_gap[i]
        extras[4, r] = road.slot_index[i]
        extras[5, r] = 0.0
        r += 1
    e = r
    for f in range(truth.shape[0]):
        if truth[f, 0] == truth[f, 0]:
            _vc_row(tables.traj, e, tables.vc_cols, at.t, truth[f])
            tables.traj_ids[e] = tables.vc_codes[f]
            e += 1
    return flags


@kernel
def _placed(kind, x, speed_in, x1, sp1, road, out):
    """The new state (x1, sp1) as SumoWorld.actuate places it: into ``out.place`` (6, n)
    SUMO's front bumper x, y [m] and angle [deg], the speed [m/s], the mean acceleration over
    the step ``road.step`` [s] [m/s^2] and the speed SUMO is told (np.maximum(v, 0)); its CoG
    ``out.pos``, ``out.vel``, ``out.heading``. Returns NOT_FINITE when the new state is not
    finite (sim/loop.py check_finite), else 0."""
    place, pos, vel, heading, step = out.place, out.pos, out.vel, out.heading, road.step
    n = x.shape[0]
    flags = 0
    for i in range(n):
        for q in range(x1.shape[1]):
            if not math.isfinite(x1[i, q]):
                flags = NOT_FINITE
    p1, v1, h1 = kinematics_rows(x1, sp1, kind)
    xf, yf, ang = cog_to_sumo_rows(p1[:, 0].copy(), p1[:, 1].copy(), h1, road.d_front)
    for i in range(n):
        before = x[i, S.V] if kind != KINEMATIC else speed_in[i]
        after = x1[i, S.V] if kind != KINEMATIC else sp1[i]
        place[0, i] = xf[i]
        place[1, i] = yf[i]
        place[2, i] = ang[i]
        place[3, i] = after
        place[4, i] = (after - before) / step
        place[5, i] = maximum(after, 0.0)  # np.maximum(v, 0.0): sumo/adapter/__init__.py set_true_speeds
        pos[i, 0] = p1[i, 0]
        pos[i, 1] = p1[i, 1]
        vel[i, 0] = v1[i, 0]
        vel[i, 1] = v1[i, 1]
        heading[i] = h1[i]
    return flags


@kernel
def _vc_row(traj, e, cols, t, truth):
    """Row ``e`` of the trajectory float block ``traj``: a virtual car (``truth``: x, y,
    theta, v, omega, v_dot, omega_dot, s; control/reference.py Reference.truth) at t [s],
    every member-only column NaN (sim/recorder.py Recorder._vc_row; ``cols``: the rows of t,
    x, y, heading, v, yaw_rate, a_lon, a_lat, s, d)."""
    for q in range(traj.shape[0]):
        traj[q, e] = np.nan
    s = truth[7]
    traj[cols[0], e] = t
    for q in range(5):
        traj[cols[1 + q], e] = truth[q]
    traj[cols[6], e] = truth[5]
    traj[cols[7], e] = truth[3] * truth[4]
    traj[cols[8], e] = s
    traj[cols[9], e] = 0.0 if s == s else np.nan
