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

from ..kernels import kernel
from .reference_road import road_reference_step, road_vc_rows


@kernel(error_model="python")
def group_reference_step(G, profs, prof_at, t_f, s, v, along, slot_d_road, is_road, d_front,
                         half_w, m_s, m_d, v_m, active, nb_rear, nb_d, nb_half_w, nb_v, nb_in_f,
                         owner, starts, lims, pps, a_vc, emergency_vc, a_cap_prev, v_prev,
                         has_prev, emergency, dt_c, vc, ramps, a_cap_from, running, a_request,
                         s_next, v_next, gap, lead_idx, a_cap_req, a_cap, truth):
    """One step of every formation f of the group (rows ``starts[f]:starts[f + 1]``, profile
    ``profs[prof_at[f]:prof_at[f + 1]]``, its own time ``t_f[f]`` [s]): per formation the
    arguments and results of :func:`road_reference_step` (``a_vc``, ``emergency_vc``,
    ``has_prev`` per formation, updated in place; ``a_request``, ``s_next``, ``v_next`` per
    formation and ``gap``, ``lead_idx``, ``a_cap_req``, ``a_cap`` per member written);
    ``truth`` (k, 8): each running formation's virtual car at t, NaN for the others. The
    neighbours a formation sees: the rows of the joined table whose ``owner`` (member row, -1
    for SUMO's vehicles) is not one of its members; its lead indices count in that subset."""
    k = s.shape[0]
    m = nb_rear.shape[0]
    for f in range(k):
        a, b = starts[f], starts[f + 1]
        if not running[f]:
            road_vc_rows(G, s[f], 0.0, 0.0, 0.0, dt_c, vc[:, a:b, :])
            truth[f, :] = np.nan
            for i in range(a, b):
                gap[i] = np.inf
                lead_idx[i] = -1
                a_cap_req[i] = 0.0
                a_cap[i] = np.inf
                a_cap_from[i] = np.inf
            a_request[f] = 0.0
            s_next[f], v_next[f] = s[f], v[f]
            continue
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
                rear[q] = nb_rear[j]
                dd[q] = nb_d[j]
                hw[q] = nb_half_w[j]
                vv[q] = nb_v[j]
                fl[q] = nb_in_f[j]
                q += 1
        a_req, a_new, em_vc, s1, v1, g, li, acr, ac = road_reference_step(
            G, profs[prof_at[f]:prof_at[f + 1]], t_f[f], s[f], v[f], np.inf, along[a:b],
            slot_d_road[a:b], is_road[a:b], d_front[a:b], half_w[a:b], m_s[a:b], m_d[a:b],
            v_m[a:b], active[a:b], rear, dd, hw, vv, lims[f], pps[f], a_vc[f], a_cap_prev[a:b],
            v_prev[a:b], has_prev[f], emergency[a:b], dt_c, vc[:, a:b, :], ramps[f],
            a_cap_from[a:b], fl, np.empty(0))  # no released member: no maneuvers in a group
        has_prev[f] = True
        a_request[f] = a_req
        a_vc[f] = a_new
        emergency_vc[f] = em_vc
        s_next[f] = s1
        v_next[f] = v1
        gap[a:b] = g
        lead_idx[a:b] = li
        a_cap_req[a:b] = acr
        a_cap[a:b] = ac
        truth[f, :] = vc[0, a, :]
