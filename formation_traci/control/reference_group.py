"""Several formations' road references in one compiled call (sim/formation_group.py).

:func:`group_reference_step` runs :func:`~.reference_road.road_reference_step`, the very
kernel a formation alone runs, for every running formation of a group over its own rows of
the joined arrays, each formation seeing as its neighbours every vehicle of the joined table
(SUMO's vehicles and every member, sumo/peers.py) but its own members; a formation that
is not running (waiting to depart, or retired) gets its virtual car standing at its s and no
virtual-car row. The numbers are those of the formations' references computed one by one. With
many rows, a formation's governor is given only the rows that can lead one of its members or
slots (:func:`_candidates`: the table ordered by arc length once a step), not every row; its
leaders, gaps and leader indices are the same (tests/test_group_candidates.py).
"""
from __future__ import annotations

import math

import numpy as np

from ..core.kernels import kernel
from .reference_records import MemberPlanner, MemberRows, NeighbourRows, RoadPlan
from .governor import LATERAL_MARGIN
from .reference_road import road_reference_step, road_vc_rows

SORTED_FROM_ROWS = 16
"""With several formations and more rows than this in the joined table, each formation reads
only its candidates (:func:`_candidates`) instead of every row: the same leaders, at a cost
that does not grow with the other formations' neighbours (tens of formations on a long road;
the bundled runs of several formations take this path too, so their golden tables check it)."""

SLACK_M = 1e-6
"""Margin [m] around the candidates' arc-length window (far above the round-off of a gap)."""


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
    sort = k > 1 and m > SORTED_FROM_ROWS
    if sort:  # each formation reads only the rows that can be its members' or slots' leaders
        order = np.argsort(nbs.rear, kind="mergesort")
        srear = nbs.rear[order]
        row_of = _row_of(owner, members.s.shape[0])
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
        if sort:
            seen, rows = _candidates(nbs, order, srear, row_of[a:b], _probes(plan, s[f], members, a, b))
        else:
            seen, rows = _seen_by(nbs, owner, a, b, m), np.empty(0, dtype=np.int64)
        a_req, a_new, em_vc, s1, v1, g, li, acr, ac = road_reference_step(
            RoadPlan(plan.G, plan.profs[plan.prof_at[f]:plan.prof_at[f + 1]], plan.along[a:b],
                     plan.slot_d[a:b], plan.is_road[a:b], plan.d_front[a:b], plan.half_w[a:b],
                     plan.lims[f], plan.pps[f], dt_c, plan.ramps[f]),
            t_f[f], s[f], v[f], a_limit[f],
            MemberRows(members.s[a:b], members.d[a:b], members.v[a:b], members.active[a:b]),
            seen, planner.a_vc[f], planner.has_prev[f],
            MemberPlanner(planner.a_cap_prev[a:b], planner.v_prev[a:b], planner.emergency[a:b]),
            vc[:, a:b, :], out.a_cap_from[a:b])  # no released member: no maneuvers in a group
        if sort:
            _seen_index(li, rows, row_of[a:b])
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


@kernel
def _row_of(owner, n):
    """Each of the n members' row in the joined table (its ``owner`` rows; -1: not in it)."""
    row = np.full(n, -1, dtype=np.int64)
    for j in range(owner.shape[0]):
        if owner[j] >= 0:
            row[owner[j]] = j
    return row


@kernel
def _probes(plan, s_f, members, a, b):
    """What the governor (control/governor.py governor_step) looks ahead from for members
    a .. b - 1 of a formation whose virtual car is at ``s_f`` [m]: (2 (b - a), 4) rows of
    front bumper's arc length [m], offset [m], half width [m] and 1.0 for a slot (0.0: the
    member), the members first, as control/reference_road.py road_reference_step computes them."""
    n = b - a
    p = np.empty((2 * n, 4))
    for q in range(n):
        i = a + q
        p[q, 0] = members.s[i] + plan.d_front[i]
        p[q, 1] = members.d[i]
        p[q, 2] = plan.half_w[i]
        p[q, 3] = 0.0
        p[n + q, 0] = (s_f + plan.along[i]) + plan.d_front[i]
        p[n + q, 1] = plan.slot_d[i] if plan.is_road[i] else members.d[i]
        p[n + q, 2] = plan.half_w[i]
        p[n + q, 3] = 1.0
    return p


@kernel
def _leads(nbs, j, probe) -> bool:
    """Can row ``j`` of ``nbs`` lead ``probe`` (a :func:`_probes` row)? governor.py
    _vehicles_ahead's test, the same arithmetic (a released member inside the formation does
    not lead a slot)."""
    if probe[3] == 1.0 and nbs.in_formation[j]:
        return False
    g = nbs.rear[j] - probe[0]
    return g > -1.0 and abs(nbs.d[j] - probe[1]) < nbs.half_w[j] + probe[2] + LATERAL_MARGIN


@kernel
def _owned(j, rows) -> int:
    """How many of a formation's member rows ``rows`` (-1: none) lie before row ``j``."""
    c = 0
    for q in range(rows.shape[0]):
        if 0 <= rows[q] < j:
            c += 1
    return c


@kernel
def _mine(j, rows) -> bool:
    """Is row ``j`` one of the formation's member rows ``rows``?"""
    for q in range(rows.shape[0]):
        if rows[q] == j:
            return True
    return False


@kernel
def _candidates(nbs, order, srear, rows, probes):
    """The rows of the joined table ``nbs`` that can lead the formation's ``probes``: every row
    but its members' (``rows``) whose rear lies from the probes' rearmost front less 1 m up to
    the rear at which every probe has found a row that leads it (:func:`_leads`; rows in order
    of rear: ``order``, ``srear``), in table order. The nearest leader of each probe is among
    them, first among equals as in the whole table. Returns them as NeighbourRows and their
    rows in the table."""
    m = srear.shape[0]
    lo = np.inf
    need = 0
    found = np.zeros(probes.shape[0], dtype=np.bool_)
    for q in range(probes.shape[0]):
        if math.isfinite(probes[q, 0]):
            lo = min(lo, probes[q, 0] - 1.0)
            need += 1
        else:
            found[q] = True  # leads nothing: its gap is NaN
    lo -= SLACK_M
    lo_i, hi_i = 0, m  # the first sorted rear >= lo
    while lo_i < hi_i:
        mid = (lo_i + hi_i) // 2
        if srear[mid] < lo:
            lo_i = mid + 1
        else:
            hi_i = mid
    end = lo_i
    top = np.inf
    while end < m:
        j = order[end]
        if need == 0 and not srear[end] <= top:
            break
        if not _mine(j, rows):
            for q in range(probes.shape[0]):
                if not found[q] and _leads(nbs, j, probes[q]):
                    found[q] = True
                    need -= 1
                    if need == 0:
                        top = srear[end] + SLACK_M
        end += 1
    keep = np.empty(end - lo_i, dtype=np.int64)
    c = 0
    for e in range(lo_i, end):
        j = order[e]
        if not _mine(j, rows):
            keep[c] = j
            c += 1
    keep = np.sort(keep[:c])
    return NeighbourRows(nbs.rear[keep], nbs.d[keep], nbs.half_w[keep], nbs.v[keep],
                         nbs.in_formation[keep], np.empty(0)), keep


@kernel
def _seen_index(li, keep, rows):
    """Leader indices ``li`` among the candidates ``keep`` (table rows) as indices among the
    rows the formation sees (:func:`_seen_by`'s: the table without its members ``rows``), in
    place."""
    for q in range(li.shape[0]):
        if li[q] >= 0:
            j = keep[li[q]]
            li[q] = j - _owned(j, rows)
