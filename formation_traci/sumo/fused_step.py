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

The arguments of :func:`fused_step`: the run's arrays first (the same objects every step),
then the step's. In groups:

fleet     ``kind`` .. ``step``: sim/fleet.py step_members' (``step`` the SUMO step [s]);
          the state ``x``, ``theta_star``, ``speed_in``, ``u_last`` at t;
sense     ``G``, ``tolerance``, ``d_front``, ``lane_table``, ``lane_points``,
          ``s_guess``, ``nb_guess``: sumo/sense.py sense_step's; ``members`` (n, 5) the
          members' SUMO rows (front bumper x, y [m], angle [deg], lateral position [m],
          lane position [m]: sumo/member_reads.py settled_members), ``li`` their packed
          lane rows, ``lane_index`` their lane indices [-]; ``nb`` (m, 7) the neighbours'
          (front bumper x, y [m], angle [deg], speed [m/s], acceleration [m/s^2], length,
          width [m]: sumo/neighbours.py neighbour_table);
reference ``profs`` .. ``truth`` and ``s``, ``v``: control/reference_group.py
          group_reference_step's, every formation running (``s``, ``v``, ``a_vc``,
          ``emergency_vc``, ``has_prev`` one per formation and the planners' arrays, the
          last three updated in place; ``frame``, ``slots`` the members' slots; each
          formation's own time t - ``depart`` [s]); ``bodies`` (4, n): the members' CoG to
          front bumper as the reference takes it, length, width and CoG to front bumper
          as SUMO has them [m]; with ``peers`` (several formations) each formation sees
          the others' members as traffic (sumo/peers.py) and ``lead_obs`` gets the
          members' leaders among SUMO's vehicles (-1: none, or a member);
record    ``sig`` (n, signal columns) the members' signals; member_signals' table
          arguments (``traj`` the trajectory table's float block, ``at`` its first row
          of the step, ``comfort``, ``comfort_ids``, ``c_at``, ``comfort_cols`` the
          comfort table's; ``limits`` the recorder's: a signal beyond them is flagged and
          its row written all the same, as the recorder writes it); ``extras`` the
          trajectory's road and SUMO columns (s, d, lane_index, sumo_gap, slot,
          leader_age_s: record/columns.py FILLED_BY_CALLER) at the same rows; ``vc_cols``
          the float-block rows of t, x, y, heading, v, yaw_rate, a_lon, a_lat, s, d of a
          virtual-car row, ``vc_codes`` each formation's vehicle_id code; ``bg_floats``,
          ``bg_ints`` the background table's blocks from row ``bg_at`` with the
          neighbours' string codes ``bg_codes`` (3, m) and lane indices;
incidents ``inc_cols`` (x, y, heading, v, v_ref columns of ``sig``), the bodies and the
          clearance matrix of sim/incidents.py member_clearances, ``stranded`` (speed
          [m/s], reference [m/s] of a stranded member);
control   ``periods`` (n_ctrl, n, 3) step_members' comfort buffer (its rows written at
          c_at + n of the comfort table);
in & out  ``active`` the members in the run (rows are recorded for them only; the others'
          SUMO rows are NaN, their ``li`` -1), ``running`` the formations running (the
          others' virtual cars stand), ``parked`` their members' rows, held at
          ``held_x`` .. ``held_ul`` (sim/formation_group.py FormationGroup.settle);
out       ``v_m`` the members' speeds [m/s] as sensed, ``m_gap`` their distance to
          where SUMO has them [m] (the sumo_gap column), ``place`` (6, n): SUMO's front
          bumper x, y [m], angle [deg], the speed [m/s] and mean acceleration [m/s^2]
          over the step of the new state and the speed SUMO is told (not below 0), and
          ``pos``, ``vel``, ``heading`` its CoG kinematics.
"""
from __future__ import annotations

import math

import numpy as np

from ..control.reference_group import group_reference_step
from ..kernels import kernel, maximum
from ..models.bicycle import S
from ..models.state import KINEMATIC
from ..sim.fleet import kinematics_rows, member_signals, step_members
from ..sim.fleet_rows import period_table_rows, signal_table_rows
from ..sim.incidents import member_clearances
from .sense import sense_step
from .types import cog_to_sumo_rows

OUT_OF_RANGE = 1
"""fused_step flag: a recorded signal is beyond the recorder's limits (a model_range event)."""
NOT_FINITE = 2
"""fused_step flag: the members' new state is not finite (sim/loop.py ModelRangeError)."""
SLOW = 4
"""fused_step flag: a member stands while its speed reference does not (sim/incidents.py)."""
EMERGENCY = 8
"""fused_step flag: the virtual car or a member is on emergency braking (sumo/events.py)."""


@kernel
def fused_step(kind, P, law, L, gains, pred, n_sub, dt_c, step, G, tolerance, d_front,
               profs, prof_at, along, slot_d, is_road, half_w, starts, lims, pps, ramps, frame,
               slots, depart, bodies, peers, a_vc, emergency_vc, has_prev, a_cap_prev, v_prev,
               emergency, vc, a_cap_from, a_request, s_next, v_next, gap, lead_idx, lead_obs,
               a_cap_req, a_cap, truth,
               sig, cols, limits, traj, traj_ids, comfort, comfort_ids, comfort_cols, extras,
               slot_index, vc_cols, vc_codes, bg_floats, bg_ints,
               inc_cols, inc_shift, inc_length, inc_width, inc_clear, stranded,
               periods, v_m, m_gap, place, pos, vel, heading,
               t, s, v, x, theta_star, speed_in, u_last, lane_table, lane_points, s_guess, members, li,
               lane_index, nb, nb_guess, bg_codes, nb_lane_index, at, c_at, bg_at, active,
               running, parked, held_x, held_ts, held_sp, held_ul):
    """One usual step of the road run at t [s]: the module docstring says what it runs and
    what each argument is ("The arguments"). Returns (x, theta_star, speed_in, u_last) after
    the step, the members' and the neighbours' arc lengths and offsets (n + m,) [m], the count
    of members farther than ``tolerance`` from where SUMO has them, the smallest clearance
    between members [m] and the flags OUT_OF_RANGE | NOT_FINITE | SLOW | EMERGENCY."""
    n = x.shape[0]
    nb_length = nb[:, 5].copy()
    nb_width = nb[:, 6].copy()
    nb_v = nb[:, 3].copy()
    pos0, vel0, hd0 = kinematics_rows(x, speed_in, kind)  # sense (SumoWorld.sense)
    s_all, d_all, v_sense, g, n_off, nb_x, nb_y, nb_psi, rear, nb_half_w = sense_step(
        G, pos0, vel0, s_guess, hd0, d_front, members[:, 0:2].copy(), members[:, 2].copy(),
        members[:, 4].copy(), members[:, 3].copy(), li, lane_table, lane_points, tolerance,
        nb[:, 0:2].copy(), nb[:, 2].copy(), nb_length, nb_width, nb_guess)
    for i in range(n):
        v_m[i] = v_sense[i]
        m_gap[i] = g[i]
    flags = _reference(G, profs, prof_at, t - depart, s, v, along, slot_d, is_road, bodies,
                       half_w, s_all[:n], d_all[:n], v_sense, active, running, rear, d_all[n:],
                       nb_half_w, nb_v, peers, starts, lims, pps, a_vc, emergency_vc, a_cap_prev,
                       v_prev, has_prev, emergency, dt_c, vc, ramps, a_cap_from, a_request,
                       s_next, v_next, gap, lead_idx, a_cap_req, a_cap, truth)
    m = nb.shape[0]
    for i in range(n):
        lead_obs[i] = lead_idx[i] if lead_idx[i] < m else -1
    _background_rows(bg_floats, bg_ints, bg_at, t, nb_x, nb_y, nb_psi, nb_v, nb[:, 4], nb_length,
                     nb_width, s_all[n:], d_all[n:], bg_codes, nb_lane_index)
    v_cap = np.full(n, np.inf)
    member_signals(x, theta_star, speed_in, u_last, kind, P, law, L, gains, pred, G, frame, vc,
                   slots, v_cap, a_cap, a_cap_from, dt_c, cols, sig, t, limits, traj, traj_ids,
                   -1, comfort, comfort_ids, c_at, comfort_cols)
    n_act = signal_table_rows(sig, t, traj, traj_ids, at, comfort, comfort_ids, c_at,
                              comfort_cols, active)
    flags |= _road_columns(sig, limits, extras, at, s_all, d_all, lane_index, g, slot_index, traj,
                           traj_ids, vc_cols, vc_codes, t, truth, inc_cols, stranded, active)
    worst = member_clearances(sig, inc_cols[0], inc_cols[1], inc_cols[2], inc_shift, inc_length,
                              inc_width, active, inc_clear)
    x1, ts1, sp1, ul1 = step_members(x, theta_star, speed_in, u_last, kind, P, law, L, gains,
                                     pred, G, frame, vc, slots, v_cap, a_cap, a_cap_from, dt_c,
                                     n_sub, periods, t, comfort, comfort_ids, -1)
    if periods.shape[0] > 1:
        period_table_rows(periods, t, dt_c, comfort, comfort_ids, c_at + n_act, active)
    for i in range(n):  # the members of formations not running stay where they are
        if parked[i]:
            x1[i] = held_x[i]
            ts1[i] = held_ts[i]
            sp1[i] = held_sp[i]
            ul1[i] = held_ul[i]
    flags |= _placed(kind, x, speed_in, x1, sp1, d_front, step, place, pos, vel, heading)
    return x1, ts1, sp1, ul1, s_all, d_all, n_off, worst, flags


@kernel
def _reference(G, profs, prof_at, t_f, s, v, along, slot_d, is_road, bodies, half_w, m_s, m_d,
               v_m, active, running, nb_rear, nb_d, nb_half_w, nb_v, peers, starts, lims, pps, a_vc,
               emergency_vc, a_cap_prev, v_prev, has_prev, emergency, dt_c, vc, ramps,
               a_cap_from, a_request, s_next, v_next, gap, lead_idx, a_cap_req, a_cap, truth):
    """Every formation's reference (group_reference_step at each formation's own time
    ``t_f`` [s], the ``running`` ones moving, no released member among the neighbours; with
    ``peers`` SUMO's vehicles joined by every member in the run: sumo/peers.py Peers.table);
    returns EMERGENCY when a running virtual car or a member in the run is on emergency
    braking, else 0."""
    k = s.shape[0]
    m = nb_rear.shape[0]
    n = 0
    if peers:
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
    for i in range(m_s.shape[0] if peers else 0):  # Peers.update's rear (front bumper less the
        if not active[i]:  # length), Peers.table's rows of the members in the run
            continue
        rear[q] = m_s[i] + bodies[3, i] - bodies[1, i]
        d[q] = m_d[i]
        half[q] = bodies[2, i] / 2
        speed[q] = v_m[i]
        owner[q] = i
        q += 1
    group_reference_step(G, profs, prof_at, t_f, s, v, along, slot_d, is_road, bodies[0].copy(),
                         half_w, m_s, m_d, v_m, active, rear, d, half, speed,
                         np.zeros(m + n, dtype=np.bool_), owner, starts, lims, pps, a_vc,
                         emergency_vc, a_cap_prev, v_prev, has_prev, emergency, dt_c, vc, ramps,
                         a_cap_from, running, a_request, s_next, v_next, gap, lead_idx, a_cap_req,
                         a_cap, truth)
    for f in range(k):
        if running[f] and emergency_vc[f]:
            return EMERGENCY
    for i in range(emergency.shape[0]):
        if emergency[i]:
            return EMERGENCY
    return 0


@kernel
def _background_rows(fl, ints, at, t, x, y, psi, v, a, length, width, s, d, codes, lane_index):
    """The neighbours' rows of the background table from row ``at`` (Recorder.add_background):
    ``fl``, ``ints`` its float and integer blocks, ``codes`` (3, m) the ids', types' and
    lanes' string codes."""
    for j in range(x.shape[0]):
        r = at + j
        fl[0, r] = t
        fl[1, r] = x[j]
        fl[2, r] = y[j]
        fl[3, r] = psi[j]
        fl[4, r] = v[j]
        fl[5, r] = a[j]
        fl[6, r] = length[j]
        fl[7, r] = width[j]
        fl[8, r] = s[j]
        fl[9, r] = d[j]
        for q in range(3):
            ints[q, r] = codes[q, j]
        ints[3, r] = lane_index[j]


@kernel
def _road_columns(sig, limits, extras, at, s_all, d_all, lane_index, gap, slot_index, traj,
                  traj_ids, vc_cols, vc_codes, t, truth, inc_cols, stranded, active):
    """After the members' rows (those in the run, ``active``): their road and SUMO columns at
    rows ``at`` .. of the trajectory table (Recorder.add_step's ``extra``), each running
    formation's virtual-car row after them; returns OUT_OF_RANGE (a signal beyond the
    recorder's ``limits``: member_signals' test) | SLOW (a member stands while its speed
    reference does not: sim/incidents.py)."""
    flags = 0
    n = sig.shape[0]
    r = at
    for i in range(n):
        for q in range(sig.shape[1]):
            if abs(sig[i, q]) > limits[q]:
                flags |= OUT_OF_RANGE
        if sig[i, inc_cols[3]] < stranded[0] and sig[i, inc_cols[4]] > stranded[1]:
            flags |= SLOW
        if not active[i]:
            continue
        extras[0, r] = s_all[i]
        extras[1, r] = d_all[i]
        extras[2, r] = lane_index[i]
        extras[3, r] = gap[i]
        extras[4, r] = slot_index[i]
        extras[5, r] = 0.0
        r += 1
    e = r
    for f in range(truth.shape[0]):
        if truth[f, 0] == truth[f, 0]:
            _vc_row(traj, e, vc_cols, t, truth[f])
            traj_ids[e] = vc_codes[f]
            e += 1
    return flags


@kernel
def _placed(kind, x, speed_in, x1, sp1, d_front, step, place, pos, vel, heading):
    """The new state (x1, sp1) as SumoWorld.actuate places it: into ``place`` (6, n) SUMO's
    front bumper x, y [m] and angle [deg], the speed [m/s], the mean acceleration over the
    ``step`` [s] [m/s^2] and the speed SUMO is told (np.maximum(v, 0)); its CoG ``pos``,
    ``vel``, ``heading``. Returns NOT_FINITE when the
    new state is not finite (sim/loop.py check_finite), else 0."""
    n = x.shape[0]
    flags = 0
    for i in range(n):
        for q in range(x1.shape[1]):
            if not math.isfinite(x1[i, q]):
                flags = NOT_FINITE
    p1, v1, h1 = kinematics_rows(x1, sp1, kind)
    xf, yf, ang = cog_to_sumo_rows(p1[:, 0].copy(), p1[:, 1].copy(), h1, d_front)
    for i in range(n):
        before = x[i, S.V] if kind != KINEMATIC else speed_in[i]
        after = x1[i, S.V] if kind != KINEMATIC else sp1[i]
        place[0, i] = xf[i]
        place[1, i] = yf[i]
        place[2, i] = ang[i]
        place[3, i] = after
        place[4, i] = (after - before) / step
        place[5, i] = maximum(after, 0.0)  # np.maximum(v, 0.0): sumo/adapter.py set_true_speeds
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
