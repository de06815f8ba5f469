"""The usual step of a road run as one compiled call.

:func:`fused_step` runs, for every member of every formation, what the loop (sim/loop.py
``step_loop``) runs in a step where nothing out of the ordinary happens, in the loop's order
and through the very kernels the loop calls one by one (the recorder, the incidents, the
peers and the world's actuate call the same row kernels on numpy arrays):

    sense      sim/fleet.py kinematics_rows, sumo/sense.py sense_step
    reference  control/reference_group.py group_reference_step (road_reference_step per
               formation: governor, planner, the virtual car's rows)
               (with several formations the members as the others' traffic: sumo/peers.py
               peer_table)
    road load  with resistances, the members' drag ratios among SUMO's vehicles (with the
               drag interaction: models/drag_interaction.py road_ratios_into) and the grade
               under them (a network with elevation: sim/road_load.py grades_into), as
               sim/road_load.py RoadLoad
    observe    the neighbours' background rows (sim/record_rows.py background_rows)
    record     sim/fleet.py member_signals (the members' trajectory and comfort rows), the
               road and SUMO columns and one virtual-car row per formation
               (sim/record_rows.py road_rows, vc_rows), the recorder's limits
               (beyond_limits), sim/incidents.py member_clearances and slow_members
    control    sim/fleet.py step_members (every control period, the comfort rows of periods
               1 .. n_ctrl - 1)
    actuate    the new state as SUMO is told it (sumo/types.py sumo_placement: poses in
               SUMO's frame, the members' speeds and mean accelerations over the step)

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
from ..core.kernels import kernel
from ..models.bicycle import S
from ..models.drag_interaction import road_ratios_into
from ..models.params import PARAM_NAMES
from ..models.state import KINEMATIC
from ..sim.fleet import kinematics_rows, member_signals, step_members
from ..sim.step_copies import with_fleet_kernels
from ..sim.fleet_rows import period_table_rows, signal_table_rows
from ..sim.incidents import member_clearances, slow_members
from ..sim.road_load import grades_into
from ..sim.record_rows import background_rows, beyond_limits, road_rows, vc_rows
from ..sim.step_flags import EMERGENCY, NOT_FINITE, OUT_OF_RANGE, SLOW
from ..sim.table_records import SignalRows
from .peers import peer_table
from .sense import NeighbourReads, SumoRows, sense_step
from .types import sumo_placement


_DRAG, _GRADE = PARAM_NAMES.index("drag_ratio"), PARAM_NAMES.index("grade")
"""The drag ratio's and the grade's columns of the members' parameters (models/params.py)."""


def fused_kernel(step, signals):
    """:func:`fused_step` for a fleet whose step and signal kernels (sim/fleet.py
    Fleet.kernels) are ``step`` and ``signals``: the cached kernel itself for the package's
    own :func:`~..sim.fleet.step_members` and :func:`~..sim.fleet.member_signals`, else a
    compiled copy calling those given (a law registered at run time: sim/fleet_laws.py
    law_kernels), made once per pair (compiled on first call, not cached on disk)."""
    return with_fleet_kernels(fused_step, _record, (step, signals))


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
    _road_load(road, fleet.P, s_all, d_all, sensed.active, nb_length, nb_width)
    m = nb.shape[0]
    for i in range(n):
        out.lead_obs[i] = ref.lead_idx[i] if ref.lead_idx[i] < m else -1
    background_rows(tables.bg_floats, tables.bg_ints, at.bg_at, t, (nb_x, nb_y, nb_psi),
                    (nb_v, nb[:, 4].copy(), nb_length, nb_width), (s_all[n:], d_all[n:]),
                    sensed.bg_codes, sensed.nb_lane_index)
    targets = StepReference(road.G, plan.frame, ref.vc, plan.slots, np.full(n, np.inf),
                            ref.a_cap, ref.a_cap_from, ~at.parked)
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
def _road_load(road, P, s_all, d_all, active, nb_length, nb_width):
    """The members' drag ratios among the neighbours and the road's grade under them into
    their parameters ``P`` (what sim/road_load.py RoadLoad gives the loop's Fleet.set_road_load),
    where the run computes them (``road.drag_law``, ``road.grade_s`` not empty); ``s_all``,
    ``d_all``: the members' then the neighbours' arc lengths and offsets [m]."""
    n = active.shape[0]
    if road.drag_law.shape[0]:
        ratio = np.empty(n)
        road_ratios_into(s_all[:n], d_all[:n], active, road.drag_bodies,
                         (s_all[n:], d_all[n:], nb_length, nb_width), road.drag_law, ratio)
        for i in range(n):
            P[i, _DRAG] = ratio[i]
    if road.grade_s.shape[0]:
        grade = np.empty(n)
        grades_into(road.grade_s, road.grade_z, s_all[:n], grade)
        for i in range(n):
            P[i, _GRADE] = grade[i]


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
    peer_table, Peers.table's); returns EMERGENCY when a running virtual car or a member in
    the run is on emergency braking, else 0."""
    nb_rear, nb_d, nb_half_w, nb_v = nbs
    bodies, running = road.bodies, at.running
    k, n = at.s.shape[0], m_s.shape[0]
    members = MemberRows(m_s, m_d, v_m, active)
    rear, d, half, speed, flags, owner = peer_table(  # with peers: the members in the run too
        NeighbourRows(nb_rear, nb_d, nb_half_w, nb_v, np.zeros(nb_rear.shape[0], dtype=np.bool_),
                      np.empty(0)),
        members if road.peers else MemberRows(m_s, m_d, v_m, np.zeros(n, dtype=np.bool_)),
        bodies[1], bodies[2], bodies[3])
    group_reference_step(plan, planner, ref, at.t - plan.depart, at.s, at.v, running,
                         at.a_limit, members, NeighbourRows(rear, d, half, speed, flags, np.empty(0)),
                         owner, dt_c)
    for f in range(k):
        if running[f] and planner.emergency_vc[f]:
            return EMERGENCY
    emergency = planner.emergency
    for i in range(emergency.shape[0]):
        if emergency[i]:
            return EMERGENCY
    return 0


@kernel
def _road_columns(out, tables, road, inc, truth, sensed, at, s_all, d_all):
    """After the members' rows (those in the run, ``sensed.active``): their road and SUMO
    columns at rows ``at.at`` .. of the trajectory table, each running formation's virtual-car
    row after them (sim/record_rows.py road_rows, vc_rows: Recorder.add_step's); returns
    OUT_OF_RANGE (a signal beyond the recorder's ``tables.limits``: record_rows.py
    beyond_limits) | SLOW (a member in the run stands while its speed reference does not:
    sim/incidents.py slow_members)."""
    flags = 0
    sig, active, n = out.sig, sensed.active, out.sig.shape[0]
    if beyond_limits(sig, tables.limits):
        flags |= OUT_OF_RANGE
    if slow_members(sig, inc.cols[3], inc.cols[4], inc.stranded, active, inc.slow):
        flags |= SLOW
    e = at.at + road_rows(tables.extras, at.at, s_all[:n], d_all[:n], sensed.lane_index, out.m_gap,
                          road.slot_index, np.zeros(n), active)  # leader_age_s: no radio
    vc_rows(tables.traj, tables.traj_ids, e, tables.vc_cols, tables.vc_codes, at.t, truth)
    return flags


@kernel
def _placed(kind, x, speed_in, x1, sp1, road, out):
    """The new state (x1, sp1) as SumoWorld.actuate places it: into ``out.place`` (6, n)
    sumo/types.py sumo_placement's rows (SUMO's front bumper x, y [m] and angle [deg], the
    speed [m/s], the mean acceleration over the step ``road.step`` [s] [m/s^2] and the speed
    SUMO is told); its CoG ``out.pos``, ``out.vel``, ``out.heading``. Returns NOT_FINITE
    when the new state is not finite (sim/loop.py check_finite), else 0."""
    pos, vel, heading = out.pos, out.vel, out.heading
    n = x.shape[0]
    flags = 0
    for i in range(n):
        for q in range(x1.shape[1]):
            if not math.isfinite(x1[i, q]):
                flags = NOT_FINITE
    p1, v1, h1 = kinematics_rows(x1, sp1, kind)
    before, after = np.empty(n), np.empty(n)  # sim/fleet.py Fleet.speed
    for i in range(n):
        before[i] = x[i, S.V] if kind != KINEMATIC else speed_in[i]
        after[i] = x1[i, S.V] if kind != KINEMATIC else sp1[i]
    sumo_placement(p1, h1, before, after, road.d_front, road.step, out.place)
    for i in range(n):
        pos[i, 0] = p1[i, 0]
        pos[i, 1] = p1[i, 1]
        vel[i, 0] = v1[i, 0]
        vel[i, 1] = v1[i, 1]
        heading[i] = h1[i]
    return flags
