"""The recorder's rows as compiled code: what sim/recorder.py Recorder writes into its tables'
buffers besides the members' signal rows (sim/fleet_rows.py), written once for every caller.
The recorder calls these kernels on numpy arrays; the compiled step of a road run
(sumo/fused_step.py) calls the same ones inside its call.

* :func:`vc_row`, :func:`vc_rows`: a virtual car's trajectory row, one per formation on the road;
* :func:`road_rows`: the trajectory's road and SUMO columns (record/columns.py FILLED_BY_CALLER
  after t and vehicle_id: s, d, lane_index, sumo_gap, slot, leader_age_s) of the members in the run;
* :func:`background_rows`: the rows of SUMO's vehicles near the formations (background table);
* :func:`beyond_limits`: a member signal beyond the recorder's limits (a ``model_range`` event
  follows, and the step's rows are written the straightforward way).

Buffers are the tables' blocks, one buffer row per column and one column per table row
(record/writer.py ChunkedTable.block); ``at`` / ``e`` name the first table row written.
"""
from __future__ import annotations

import numpy as np

from ..core.kernels import kernel


@kernel
def vc_row(traj, e, cols, t, truth):
    """Row ``e`` of the trajectory float block ``traj``: a virtual car (``truth``: x, y, theta,
    v, omega, v_dot, omega_dot, s; control/reference.py Reference.truth) at t [s], every
    member-only column NaN (``cols``: the block rows of t, x, y, heading, v, yaw_rate, a_lon,
    a_lat, s, d; a_lat = v omega, d = 0 where s is known)."""
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


@kernel
def vc_rows(traj, traj_ids, e, cols, codes, t, truth):
    """One :func:`vc_row` from row ``e`` for every virtual car of ``truth`` (k, 8) on the road
    (a NaN row: its formation waits to depart or is done), its vehicle_id code ``codes[f]``
    into ``traj_ids``; returns how many rows."""
    r = e
    for f in range(truth.shape[0]):
        if truth[f, 0] == truth[f, 0]:
            vc_row(traj, r, cols, t, truth[f])
            traj_ids[r] = codes[f]
            r += 1
    return r - e


@kernel
def road_rows(extras, at, s, d, lane_index, gap, slot, age, active):
    """The road and SUMO columns of the members with ``active`` (in order, one table row
    each from ``at``) into ``extras`` (6, rows): arc length ``s``, offset ``d`` [m], lane index,
    ``gap`` to where SUMO has the member (sumo_gap) [m], ``slot`` index and ``age`` of the
    virtual car's copy (leader_age_s) [s], each (n,); returns how many rows."""
    r = at
    for i in range(s.shape[0]):
        if not active[i]:
            continue
        extras[0, r] = s[i]
        extras[1, r] = d[i]
        extras[2, r] = lane_index[i]
        extras[3, r] = gap[i]
        extras[4, r] = slot[i]
        extras[5, r] = age[i]
        r += 1
    return r - at


@kernel
def background_rows(floats, ints, at, t, pose, body, sd, codes, lane_index):
    """SUMO's vehicles near the formations at t [s] as background rows from ``at``: ``pose``
    (x, y [m], heading [rad]) of their body centres, ``body`` (speed [m/s], acceleration
    [m/s^2], length, width [m]), ``sd`` (arc length s, offset d [m]) into ``floats`` (t, x, y,
    heading, v, a, length, width, s, d); their id, type and lane codes ``codes`` (3, m) and
    lane indices into ``ints``."""
    x, y, psi = pose
    v, a, length, width = body
    s, d = sd
    for j in range(x.shape[0]):
        r = at + j
        floats[0, r] = t
        floats[1, r] = x[j]
        floats[2, r] = y[j]
        floats[3, r] = psi[j]
        floats[4, r] = v[j]
        floats[5, r] = a[j]
        floats[6, r] = length[j]
        floats[7, r] = width[j]
        floats[8, r] = s[j]
        floats[9, r] = d[j]
        for q in range(3):
            ints[q, r] = codes[q, j]
        ints[3, r] = lane_index[j]


@kernel
def beyond_limits(sig, limits):
    """Is any |signal| of ``sig`` (n, signal columns) beyond its column's bound ``limits``
    (NaN is not)?"""
    for i in range(sig.shape[0]):
        for q in range(sig.shape[1]):
            if abs(sig[i, q]) > limits[q]:
                return True
    return False


def warm_kernels() -> None:
    """Compile the kernels above for the arguments the recorder passes (sim/warm.py: some are
    called only on rare steps, such as a part file ending inside a step)."""
    f, ids, cols = np.empty((10, 1)), np.zeros(1, dtype=np.int32), np.arange(10)
    e, ints = np.empty(0), np.empty((4, 1), dtype=np.int32)
    vc_row(f, 0, cols, 0.0, np.zeros(8))
    vc_rows(f, ids, 0, cols, ids, 0.0, np.full((1, 8), np.nan))
    road_rows(f, 0, e, e, e, e, e, e, np.empty(0, dtype=np.bool_))
    background_rows(f, ints, 0, 0.0, (e, e, e), (e, e, e, e), (e, e), np.empty((3, 0), dtype=np.int32),
                    np.empty(0, dtype=np.int64))
    beyond_limits(np.empty((0, 1)), e)
