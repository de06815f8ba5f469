"""Several formations' road references in one compiled call (sim/formation_group.py).

:func:`group_reference_step` runs :func:`~.reference_road.road_reference_step`, the very
kernel a formation alone runs, for every running formation of a group over its own rows of
the joined arrays, each formation seeing as its neighbours every vehicle of the joined table
(SUMO's vehicles and every member, sumo/peers.py) but its own members; a formation that
is not running (waiting to depart, or retired) gets its virtual car standing at its s and no
virtual-car row. The numbers are those of the formations' references computed one by one.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel
from .reference_records import MemberPlanner, MemberRows, NeighbourRows, RoadPlan
from .reference_road import road_reference_step, road_vc_rows


@kernel(error_model="python")
def group_reference_step(plan, planner, out, t_f, s, v, running, a_limit, members, nbs, owner, dt_c):
    """One step of every formation f of the group (``plan``: control/reference_records.py
    GroupPlan, rows ``starts[f]:starts[f + 1]``, profile ``profs[prof_at[f]:prof_at[f + 1]]``,
    its own time ``t_f[f]`` [s], virtual car at ``s[f]`` [m], ``v[f]`` [m/s]): per formation
    the arguments and results of :func:`road_reference_step` (``planner``: PlannerState, its
    ``a_vc``, ``emergency_vc``, ``has_prev`` per formation, updated in place; ``out``:
    ReferenceOut, ``a_request``, ``s_next``, ``v_next`` per formation and ``gap``,
    ``lead_idx``, ``a_cap_req``, ``a_cap`` per member written, ``truth`` (k, 8) each running
    formation's virtual car at t, NaN for the others). ``members``: MemberRows of every
    member; ``a_limit`` (k,): the world's cap on each formation's requested acceleration
    [m/s^2] (inf: none; ramp traffic); ``nbs``: NeighbourRows of the joined table (``mate_rear`` unused). The neighbours
    a formation sees: the rows of the joined table whose ``owner`` (member row, -1 for SUMO's
    vehicles) is not one of its members; its lead indices count in that subset."""
    starts, vc, truth = plan.starts, out.vc, out.truth
    k = s.shape[0]
    m = nbs.rear.shape[0]
    for f in range(k):
        a, b = starts[f], starts[f + 1]
        if not running[f]:
            road_vc_rows(plan.G, s[f], 0.0, 0.0, 0.0, dt_c, vc[:, a:b, :])
            truth[f, :] = np.nan
            for i in range(a, b):
                out.gap[i] = np.inf
                out.lead_idx[i] = -1
                out.a_cap_req[i] = 0.0
                out.a_cap[i] = np.inf
                out.a_cap_from[i] = np.inf
            out.a_request[f] = 0.0
            out.s_next[f], out.v_next[f] = s[f], v[f]
            continue
        a_req, a_new, em_vc, s1, v1, g, li, acr, ac = road_reference_step(
            RoadPlan(plan.G, plan.profs[plan.prof_at[f]:plan.prof_at[f + 1]], plan.along[a:b],
                     plan.slot_d[a:b], plan.is_road[a:b], plan.d_front[a:b], plan.half_w[a:b],
                     plan.lims[f], plan.pps[f], dt_c, plan.ramps[f]),
            t_f[f], s[f], v[f], a_limit[f],
            MemberRows(members.s[a:b], members.d[a:b], members.v[a:b], members.active[a:b]),
            _seen_by(nbs, owner, a, b, m), planner.a_vc[f], planner.has_prev[f],
            MemberPlanner(planner.a_cap_prev[a:b], planner.v_prev[a:b], planner.emergency[a:b]),
            vc[:, a:b, :], out.a_cap_from[a:b])  # no released member: no maneuvers in a group
        planner.has_prev[f] = True
        out.a_request[f] = a_req
        planner.a_vc[f] = a_new
        planner.emergency_vc[f] = em_vc
        out.s_next[f] = s1
        out.v_next[f] = v1
        out.gap[a:b] = g
        out.lead_idx[a:b] = li
        out.a_cap_req[a:b] = acr
        out.a_cap[a:b] = ac
        truth[f, :] = vc[0, a, :]


@kernel
def _seen_by(nbs, owner, a, b, m):
    """The rows of the joined neighbour table ``nbs`` (m rows) the formation of member rows
    a .. b - 1 sees: every row whose ``owner`` is not one of its members."""
    keep = 0
    for j in range(m):
        if owner[j] < a or owner[j] >= b:
            keep += 1
    rear = np.empty(keep)
    dd = np.empty(keep)
    hw = np.empty(keep)
    vv = np.empty(keep)
    fl = np.zeros(keep, dtype=np.bool_)
    q = 0
    for j in range(m):
        if owner[j] < a or owner[j] >= b:
            rear[q] = nbs.rear[j]
            dd[q] = nbs.d[j]
            hw[q] = nbs.half_w[j]
            vv[q] = nbs.v[j]
            fl[q] = nbs.in_formation[j]
            q += 1
    return NeighbourRows(rear, dd, hw, vv, fl, np.empty(0))
